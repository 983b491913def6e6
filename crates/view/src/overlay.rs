//! Text drawn over a frame (the statistics line, the help): an 8x8 bitmap font, on a dark band
//! so that it reads over any picture.

/// Draws `lines` into the RGB8 image `rgb` (`w` x `h`) from its top-left corner, each glyph
/// scaled by `scale`, light text on a dimmed band.
pub fn draw_lines(rgb: &mut [u8], w: u32, h: u32, lines: &[String], scale: u32) {
    let scale = scale.max(1);
    let (gw, gh) = (8 * scale, 10 * scale);
    let width = lines.iter().map(|l| l.chars().count() as u32).max().unwrap_or(0) * gw + 2 * scale;
    let height = lines.len() as u32 * gh + scale;
    // The band: the picture below at a third of its brightness.
    for y in 0..height.min(h) {
        for x in 0..width.min(w) {
            let i = 3 * (y * w + x) as usize;
            for c in &mut rgb[i..i + 3] {
                *c /= 3;
            }
        }
    }
    for (row, line) in lines.iter().enumerate() {
        for (col, ch) in line.chars().enumerate() {
            // Printable ASCII (the basic Latin block of the font), others left blank.
            let Some(glyph) = font8x8::legacy::BASIC_LEGACY.get(ch as usize).filter(|_| ch.is_ascii()) else {
                continue;
            };
            let (x0, y0) = (scale + col as u32 * gw, scale + row as u32 * gh);
            for (gy, bits) in glyph.iter().enumerate() {
                for gx in 0..8 {
                    if bits & (1 << gx) == 0 {
                        continue;
                    }
                    for sy in 0..scale {
                        for sx in 0..scale {
                            let (x, y) = (x0 + gx * scale + sx, y0 + gy as u32 * scale + sy);
                            if x < w && y < h {
                                let i = 3 * (y * w + x) as usize;
                                rgb[i..i + 3].copy_from_slice(&[240, 240, 235]);
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Text lights pixels where its glyphs are, and dims the band under it; nothing is drawn
    /// past the image's edge.
    #[test]
    fn text_is_drawn_within_the_image() {
        let (w, h) = (40, 12);
        let mut rgb = vec![90u8; (3 * w * h) as usize];
        draw_lines(&mut rgb, w, h, &["Hi megaray".to_string()], 1);
        let lit = rgb.chunks(3).filter(|p| p[0] == 240).count();
        let dim = rgb.chunks(3).filter(|p| p[0] == 30).count();
        assert!(lit > 10 && dim > 100, "{lit} lit, {dim} dimmed");
        assert_eq!(rgb.len(), (3 * w * h) as usize);
    }
}
