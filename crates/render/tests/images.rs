//! Output files: the EXR holds the float buffer exactly, the PNG holds its tone mapping.

use megaray_base::{hash32, u01};
use megaray_render::*;

fn noise_image(w: u32, h: u32, seed: u32) -> Image {
    let mut img = Image::new(w, h);
    for (i, p) in img.pixels.iter_mut().enumerate() {
        for (k, c) in p.iter_mut().enumerate() {
            // Values over several stops, some above 1.
            *c = 4.0 * u01(hash32(seed ^ hash32((3 * i + k) as u32))).powi(3);
        }
    }
    img
}

#[test]
fn exr_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let img = noise_image(37, 21, 1);
    let n = img.pixels.len();
    let aovs = Aovs {
        depth: Some((0..n).map(|i| if i % 7 == 0 { f32::INFINITY } else { i as f32 * 0.25 }).collect()),
        normal: Some(noise_image(37, 21, 2).pixels),
        albedo: Some(noise_image(37, 21, 3).pixels),
    };
    let path = dir.path().join("out.exr");
    img.save_exr(&path, Some(&aovs)).unwrap();
    let (back, back_aovs) = read_exr(&path).unwrap();
    assert_eq!(back, img);
    assert_eq!(back_aovs, aovs);
    // Without AOVs: colour only.
    img.save_exr(&path, None).unwrap();
    let (back, back_aovs) = read_exr(&path).unwrap();
    assert_eq!(back, img);
    assert_eq!(back_aovs, Aovs::default());
    // No temporary file is left beside it.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn png_is_the_tone_mapped_buffer() {
    let dir = tempfile::tempdir().unwrap();
    let img = noise_image(19, 11, 4);
    for tm in [
        ToneMap::default(),
        ToneMap { exposure: -1.5, curve: ToneCurve::Clamp },
        ToneMap { exposure: 1.0, curve: ToneCurve::Reinhard },
    ] {
        let path = dir.path().join("out.png");
        img.save_png_with(&path, &tm).unwrap();
        let back = image::open(&path).unwrap().into_rgb8();
        assert_eq!(back.dimensions(), (19, 11));
        // Byte for byte the documented mapping: scale by 2^exposure, curve, sRGB.
        let expect: Vec<u8> = img
            .pixels
            .iter()
            .flatten()
            .map(|&x| {
                let x = x * tm.exposure.exp2();
                let y = match tm.curve {
                    ToneCurve::Clamp => x.min(1.0),
                    ToneCurve::Reinhard => x / (1.0 + x),
                };
                let s = if y <= 0.003_130_8 { 12.92 * y } else { 1.055 * y.powf(1.0 / 2.4) - 0.055 };
                (s * 255.0 + 0.5) as u8
            })
            .collect();
        assert_eq!(back.as_raw(), &expect);
    }
    assert_eq!(srgb(0.0), 0);
    assert_eq!(srgb(1.0), 255);
    assert_eq!(srgb(0.5), 188);
    // The table gives what the formula gives, over every 61st float in [0, 1] and past it.
    for bits in (0..=1.0f32.to_bits() + 1000).step_by(61).chain([1.0f32.to_bits()]) {
        let x = f32::from_bits(bits);
        assert_eq!(srgb_by_table(x), srgb(x), "at {x:e}");
    }
    for x in [-1.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 2.0] {
        assert_eq!(srgb_by_table(x), srgb(x), "at {x}");
    }
}

/// Environment maps the fuzzer (fuzz/, target `env`) found making the decoder allocate
/// gigabytes from a lying header: each is now one line of error naming the file (or loads).
#[test]
fn environment_maps_found_by_fuzzing_are_one_line_errors() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz/env");
    let mut n = 0;
    for f in std::fs::read_dir(&dir).unwrap() {
        let path = f.unwrap().path();
        n += 1;
        if let Err(e) = EnvMap::load(&path) {
            let msg = e.to_string();
            assert_eq!(msg.lines().count(), 1, "{msg}");
            assert!(msg.contains(&*path.to_string_lossy()), "{msg}");
        }
        if path.extension().is_some_and(|e| e == "exr") {
            if let Err(e) = read_exr(&path) {
                assert_eq!(e.to_string().lines().count(), 1, "{e}");
            }
        }
    }
    assert!(n >= 22, "only {n} inputs");
}
