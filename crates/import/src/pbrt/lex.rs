//! pbrt-v4's tokens: identifiers, quoted strings, numbers, brackets; `#` comments. Each
//! token keeps its line and column for error messages (`file:line:col`, as pbrt's own).

use std::path::{Path, PathBuf};

use crate::ImportError;

#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Tok {
    Ident(String),
    Str(String),
    Num(f64),
    Open,
    Close,
}

/// Where a token starts: file, line and column (1-based).
#[derive(Clone, Debug)]
pub(crate) struct Loc {
    pub(crate) file: PathBuf,
    pub(crate) line: u32,
    pub(crate) col: u32,
}

impl Loc {
    /// An error at this place.
    pub(crate) fn err(&self, msg: impl Into<String>) -> ImportError {
        ImportError::new(&self.file, Some(format!("line {}:{}", self.line, self.col)), msg)
    }
}

/// The tokens of one file, read on demand.
pub(crate) struct Lexer {
    file: PathBuf,
    text: Vec<u8>,
    at: usize,
    line: u32,
    col: u32,
    peeked: Option<(Tok, Loc)>,
}

impl Lexer {
    pub(crate) fn open(path: &Path) -> Result<Lexer, ImportError> {
        let text = std::fs::read(path).map_err(|e| ImportError::new(path, None, format!("cannot read: {e}")))?;
        let text = if path.extension().is_some_and(|e| e == "gz") {
            let mut out = Vec::new();
            std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&text[..]), &mut out)
                .map_err(|e| ImportError::new(path, None, format!("cannot decompress: {e}")))?;
            out
        } else {
            text
        };
        Ok(Lexer::new(path, text))
    }

    pub(crate) fn new(path: &Path, text: Vec<u8>) -> Lexer {
        Lexer { file: path.to_path_buf(), text, at: 0, line: 1, col: 1, peeked: None }
    }

    pub(crate) fn file(&self) -> &Path {
        &self.file
    }

    fn here(&self) -> Loc {
        Loc { file: self.file.clone(), line: self.line, col: self.col }
    }

    fn bump(&mut self) -> Option<u8> {
        let c = *self.text.get(self.at)?;
        self.at += 1;
        if c == b'\n' {
            self.line += 1;
            self.col = 1;
        } else {
            self.col += 1;
        }
        Some(c)
    }

    pub(crate) fn peek(&mut self) -> Result<Option<&(Tok, Loc)>, ImportError> {
        if self.peeked.is_none() {
            self.peeked = self.read()?;
        }
        Ok(self.peeked.as_ref())
    }

    pub(crate) fn next(&mut self) -> Result<Option<(Tok, Loc)>, ImportError> {
        match self.peeked.take() {
            Some(t) => Ok(Some(t)),
            None => self.read(),
        }
    }

    fn read(&mut self) -> Result<Option<(Tok, Loc)>, ImportError> {
        loop {
            match self.text.get(self.at) {
                None => return Ok(None),
                Some(c) if c.is_ascii_whitespace() => {
                    self.bump();
                }
                Some(b'#') => while self.bump().is_some_and(|c| c != b'\n') {},
                Some(_) => break,
            }
        }
        let loc = self.here();
        let c = self.bump().expect("a byte is there");
        let tok = match c {
            b'[' => Tok::Open,
            b']' => Tok::Close,
            b'"' => {
                let mut s = Vec::new();
                loop {
                    match self.bump() {
                        None | Some(b'\n') => return Err(loc.err("unterminated string")),
                        Some(b'"') => break,
                        Some(b'\\') => match self.bump() {
                            Some(b'n') => s.push(b'\n'),
                            Some(b't') => s.push(b'\t'),
                            Some(c) => s.push(c),
                            None => return Err(loc.err("unterminated string")),
                        },
                        Some(c) => s.push(c),
                    }
                }
                Tok::Str(String::from_utf8_lossy(&s).into_owned())
            }
            _ => {
                let start = self.at - 1;
                while self.text.get(self.at).is_some_and(|c| !c.is_ascii_whitespace() && !b"[]\"#".contains(c)) {
                    self.bump();
                }
                let word = String::from_utf8_lossy(&self.text[start..self.at]).into_owned();
                if c.is_ascii_alphabetic() {
                    Tok::Ident(word)
                } else {
                    match word.parse::<f64>() {
                        Ok(v) if v.is_finite() => Tok::Num(v),
                        _ => return Err(loc.err(format!("unexpected token '{word}'"))),
                    }
                }
            }
        };
        Ok(Some((tok, loc)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_and_places() {
        let mut l = Lexer::new(Path::new("t.pbrt"), b"Shape \"trianglemesh\" # c\n  [ 1 -2.5e1 ]".to_vec());
        let mut toks = Vec::new();
        while let Some((t, loc)) = l.next().unwrap() {
            toks.push((t, loc.line, loc.col));
        }
        assert_eq!(
            toks,
            vec![
                (Tok::Ident("Shape".into()), 1, 1),
                (Tok::Str("trianglemesh".into()), 1, 7),
                (Tok::Open, 2, 3),
                (Tok::Num(1.0), 2, 5),
                (Tok::Num(-25.0), 2, 7),
                (Tok::Close, 2, 14),
            ]
        );
        let e = Lexer::new(Path::new("t.pbrt"), b"\n  \"open".to_vec()).next().unwrap_err().to_string();
        assert!(e.contains("line 2:3") && e.contains("unterminated string"), "{e}");
        let e = Lexer::new(Path::new("t.pbrt"), b"Shape @x".to_vec());
        let mut e = e;
        e.next().unwrap();
        assert!(e.next().unwrap_err().to_string().contains("line 1:7"));
    }
}
