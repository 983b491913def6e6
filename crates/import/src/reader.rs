//! A buffered byte reader shared by the streaming readers.
//!
//! [`ByteReader`] keeps one large buffer over any [`Read`], hands out slices of it (fixed-size
//! records for binary formats, lines and whitespace-separated tokens for ascii formats),
//! tracks the file offset and the current line number, and reports every byte it pulls from
//! the input to a [`Progress`]. Nothing it does allocates in proportion to the input: the
//! buffer only grows when a single line or token is longer than it, and never past the
//! `max_line` given to [`ByteReader::read_line`] or [`ByteReader::next_token`].

use std::io::{self, Read};

use megaray_base::Progress;

/// Default buffer size: large enough for hundreds of MB/s, small against any memory budget.
pub(crate) const DEFAULT_BUF: usize = 1 << 20;

/// Progress is reported in chunks of at least this many bytes.
const PROGRESS_CHUNK: u64 = 4 << 20;

/// A buffered reader over `R` that yields records, lines and tokens as borrowed slices.
pub(crate) struct ByteReader<'p, R> {
    inner: R,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    /// File offset of `buf[start]`.
    offset: u64,
    eof: bool,
    progress: &'p dyn Progress,
    /// Bytes read from `inner` but not yet reported to `progress`.
    unreported: u64,
    /// Total bytes read from `inner`.
    total: u64,
    /// 1-based number of the line the reader is at (text formats only).
    line: u64,
}

/// An error of [`ByteReader::read_line`] / [`ByteReader::next_token`] beyond plain I/O.
#[derive(Debug)]
pub(crate) enum TextError {
    /// Reading failed.
    Io(io::Error),
    /// A line or token is longer than the allowed maximum.
    TooLong(usize),
}

impl From<io::Error> for TextError {
    fn from(e: io::Error) -> Self {
        TextError::Io(e)
    }
}

impl std::fmt::Display for TextError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TextError::Io(e) => write!(f, "read error: {e}"),
            TextError::TooLong(n) => write!(f, "line or token longer than {n} bytes (not a text file?)"),
        }
    }
}

#[inline]
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\n' | b'\r' | 0x0b | 0x0c)
}

impl<'p, R: Read> ByteReader<'p, R> {
    /// A reader with a buffer of `cap` bytes reporting to `progress`.
    pub(crate) fn new(inner: R, cap: usize, progress: &'p dyn Progress) -> Self {
        ByteReader {
            inner,
            buf: vec![0; cap.max(64)],
            start: 0,
            end: 0,
            offset: 0,
            eof: false,
            progress,
            unreported: 0,
            total: 0,
            line: 1,
        }
    }

    /// File offset of the next unread byte.
    #[inline]
    pub(crate) fn offset(&self) -> u64 {
        self.offset
    }

    /// Total number of bytes pulled from the input so far.
    pub(crate) fn total_read(&self) -> u64 {
        self.total
    }

    /// The 1-based number of the line the reader is at: the line the next
    /// [`ByteReader::read_line`] returns (tokens report their own line).
    #[inline]
    pub(crate) fn line(&self) -> u64 {
        self.line
    }

    /// Capacity of the buffer.
    #[inline]
    pub(crate) fn capacity(&self) -> usize {
        self.buf.len()
    }

    /// The buffered, unread bytes.
    #[inline]
    pub(crate) fn available(&self) -> &[u8] {
        &self.buf[self.start..self.end]
    }

    /// Marks `n` buffered bytes as read.
    #[inline]
    pub(crate) fn consume(&mut self, n: usize) {
        debug_assert!(n <= self.end - self.start);
        self.start += n;
        self.offset += n as u64;
    }

    /// Reports pending progress.
    pub(crate) fn flush_progress(&mut self) {
        if self.unreported > 0 {
            self.progress.inc(self.unreported);
            self.unreported = 0;
        }
    }

    /// Makes at least `n` bytes available (growing the buffer if `n` exceeds it). Returns
    /// `false` when the input ends first; whatever it holds is then available.
    pub(crate) fn fill_to(&mut self, n: usize) -> io::Result<bool> {
        if self.end - self.start >= n {
            return Ok(true);
        }
        if n > self.buf.len() {
            let len = self.end - self.start;
            self.buf.copy_within(self.start..self.end, 0);
            self.start = 0;
            self.end = len;
            self.buf.resize(n.max(self.buf.len() * 2), 0);
        } else if self.buf.len() - self.start < n {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        while self.end - self.start < n {
            if self.eof {
                return Ok(false);
            }
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => self.eof = true,
                Ok(k) => {
                    self.end += k;
                    self.total += k as u64;
                    self.unreported += k as u64;
                    if self.unreported >= PROGRESS_CHUNK {
                        self.flush_progress();
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(true)
    }

    /// Reads exactly `n` bytes, or `None` when the input ends first.
    #[inline]
    pub(crate) fn take(&mut self, n: usize) -> io::Result<Option<&[u8]>> {
        if self.end - self.start < n && !self.fill_to(n)? {
            return Ok(None);
        }
        let s = self.start;
        self.consume(n);
        Ok(Some(&self.buf[s..s + n]))
    }

    /// Skips `n` bytes; returns how many were skipped (fewer when the input ends first).
    pub(crate) fn skip(&mut self, mut n: u64) -> io::Result<u64> {
        let want = n;
        while n > 0 {
            if self.start == self.end && !self.fill_to(1)? {
                break;
            }
            let k = ((self.end - self.start) as u64).min(n) as usize;
            self.consume(k);
            n -= k as u64;
        }
        Ok(want - n)
    }

    /// Reads one line, without its `\n` (and `\r\n`). `None` at the end of the input.
    /// Lines longer than `max_line` bytes are an error.
    pub(crate) fn read_line(&mut self, max_line: usize) -> Result<Option<&[u8]>, TextError> {
        let mut scanned = 0;
        loop {
            let avail = &self.buf[self.start + scanned..self.end];
            if let Some(i) = avail.iter().position(|&b| b == b'\n') {
                let s = self.start;
                let len = scanned + i;
                self.consume(len + 1);
                self.line += 1;
                let mut line = &self.buf[s..s + len];
                if let [rest @ .., b'\r'] = line {
                    line = rest;
                }
                return Ok(Some(line));
            }
            scanned = self.end - self.start;
            if scanned > max_line {
                return Err(TextError::TooLong(max_line));
            }
            if !self.fill_to(scanned + 1)? && self.end - self.start == scanned {
                // End of input: the rest is the last line.
                if scanned == 0 {
                    return Ok(None);
                }
                let s = self.start;
                self.consume(scanned);
                self.line += 1;
                let mut line = &self.buf[s..s + scanned];
                if let [rest @ .., b'\r'] = line {
                    line = rest;
                }
                return Ok(Some(line));
            }
        }
    }

    /// Reads the next whitespace-separated token and the number of its line (`None` at the
    /// end of the input), counting the newlines it passes.
    pub(crate) fn next_token(&mut self, max_token: usize) -> Result<Option<(u64, &[u8])>, TextError> {
        // Skip whitespace.
        loop {
            let avail = &self.buf[self.start..self.end];
            let mut i = 0;
            let mut lines = 0;
            while i < avail.len() && is_space(avail[i]) {
                lines += (avail[i] == b'\n') as u64;
                i += 1;
            }
            self.line += lines;
            self.consume(i);
            if self.start < self.end {
                break;
            }
            if !self.fill_to(1)? {
                return Ok(None);
            }
        }
        // Scan the token.
        let mut scanned = 0;
        loop {
            let avail = &self.buf[self.start + scanned..self.end];
            if let Some(i) = avail.iter().position(|&b| is_space(b)) {
                let s = self.start;
                let len = scanned + i;
                self.consume(len);
                return Ok(Some((self.line, &self.buf[s..s + len])));
            }
            scanned = self.end - self.start;
            if scanned > max_token {
                return Err(TextError::TooLong(max_token));
            }
            if !self.fill_to(scanned + 1)? && self.end - self.start == scanned {
                let s = self.start;
                self.consume(scanned);
                return Ok(Some((self.line, &self.buf[s..s + scanned])));
            }
        }
    }
}

impl<R> Drop for ByteReader<'_, R> {
    fn drop(&mut self) {
        if self.unreported > 0 {
            self.progress.inc(self.unreported);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use megaray_base::NoProgress;

    /// A reader that returns at most 3 bytes per call, to exercise refills.
    struct Dribble<'a>(&'a [u8]);
    impl Read for Dribble<'_> {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            let n = self.0.len().min(out.len()).min(3);
            out[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    #[test]
    fn lines_across_refills_and_growth() {
        let text = b"first\r\nsecond line is long\n\nlast";
        let mut r = ByteReader::new(Dribble(text), 64, &NoProgress);
        let mut got = Vec::new();
        while let Some(l) = r.read_line(1000).unwrap() {
            got.push(String::from_utf8(l.to_vec()).unwrap());
        }
        assert_eq!(got, ["first", "second line is long", "", "last"]);
        assert_eq!(r.offset(), text.len() as u64);

        let long = vec![b'a'; 300];
        let mut r = ByteReader::new(&long[..], 64, &NoProgress);
        assert_eq!(r.read_line(1000).unwrap().unwrap().len(), 300);
        let mut r = ByteReader::new(&long[..], 64, &NoProgress);
        assert!(matches!(r.read_line(100), Err(TextError::TooLong(100))));
    }

    #[test]
    fn tokens_count_lines() {
        let text = b"  a bb\n\n ccc\t\r\nd";
        let mut r = ByteReader::new(Dribble(text), 64, &NoProgress);
        let mut got = Vec::new();
        while let Some((line, t)) = r.next_token(100).unwrap() {
            got.push((String::from_utf8(t.to_vec()).unwrap(), line));
        }
        let want: Vec<(String, u64)> =
            [("a", 1), ("bb", 1), ("ccc", 3), ("d", 4)].iter().map(|(s, l)| (s.to_string(), *l)).collect();
        assert_eq!(got, want);
    }

    #[test]
    fn take_and_skip() {
        let data: Vec<u8> = (0..200u8).collect();
        let mut r = ByteReader::new(Dribble(&data), 64, &NoProgress);
        assert_eq!(r.take(3).unwrap().unwrap(), &[0, 1, 2]);
        assert_eq!(r.skip(100).unwrap(), 100);
        assert_eq!(r.take(50).unwrap().unwrap()[0], 103);
        assert_eq!(r.offset(), 153);
        assert!(r.take(100).unwrap().is_none());
        assert_eq!(r.skip(1000).unwrap(), 47);
        assert_eq!(r.offset(), 200);
    }
}
