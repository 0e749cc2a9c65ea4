//! A byte tokenizer for the text formats (ASCII PLY and STL) that tracks line and column.

use std::fmt::Display;
use std::path::Path;

use crate::error::{Error, Location};

/// A whitespace-separated token and where it starts.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Token<'a> {
    pub bytes: &'a [u8],
    pub loc: Location,
}

impl Token<'_> {
    /// The token as text, for messages (invalid UTF-8 replaced, long tokens cut).
    pub fn text(&self) -> String {
        let s = String::from_utf8_lossy(self.bytes);
        if s.chars().count() > 40 {
            format!("{}...", s.chars().take(40).collect::<String>())
        } else {
            s.into_owned()
        }
    }

    pub fn is(&self, word: &str) -> bool {
        self.bytes.eq_ignore_ascii_case(word.as_bytes())
    }

    pub fn parse_f64(&self) -> Option<f64> {
        std::str::from_utf8(self.bytes).ok()?.parse().ok()
    }

    pub fn parse_i64(&self) -> Option<i64> {
        std::str::from_utf8(self.bytes).ok()?.parse().ok()
    }
}

/// `s` (text from a file) fit for a one-line message: control characters such as line
/// ends escaped, cut after `max` characters.
pub(crate) fn one_line(s: &str, max: usize) -> String {
    let mut out = String::new();
    for c in s.chars().take(max) {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    if s.chars().nth(max).is_some() {
        out.push_str("...");
    }
    out
}

/// A warning for [`super::LoadReport::warnings`]: one line naming the file, the place
/// (where known) and the problem, formatted as an input error is.
pub(crate) fn warning(path: &Path, location: Option<Location>, message: impl Display) -> String {
    Error::input(path, location, message).to_string()
}

fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | b'\n' | 0x0b | 0x0c)
}

/// Splits bytes into tokens, counting lines.
pub(crate) struct Tokens<'a> {
    data: &'a [u8],
    pos: usize,
    line: usize,
    line_start: usize,
}

impl<'a> Tokens<'a> {
    /// Tokens of `data[start..]`, where `data[start]` is at the start of line `line`.
    pub fn new(data: &'a [u8], start: usize, line: usize) -> Self {
        Tokens { data, pos: start.min(data.len()), line, line_start: start.min(data.len()) }
    }

    /// Where the next byte is.
    pub fn location(&self) -> Location {
        Location { line: self.line, column: self.pos - self.line_start + 1 }
    }

    fn skip_space(&mut self, stop_at_newline: bool) {
        while let Some(&b) = self.data.get(self.pos) {
            if !is_space(b) || (stop_at_newline && b == b'\n') {
                break;
            }
            self.pos += 1;
            if b == b'\n' {
                self.line += 1;
                self.line_start = self.pos;
            }
        }
    }

    fn take(&mut self) -> Option<Token<'a>> {
        let start = self.pos;
        let loc = self.location();
        while self.pos < self.data.len() && !is_space(self.data[self.pos]) {
            self.pos += 1;
        }
        (self.pos > start).then(|| Token { bytes: &self.data[start..self.pos], loc })
    }

    /// The next token, across line ends.
    pub fn next_token(&mut self) -> Option<Token<'a>> {
        self.skip_space(false);
        self.take()
    }

    /// The next token on the current line, or `None` at the line's end.
    pub fn next_on_line(&mut self) -> Option<Token<'a>> {
        self.skip_space(true);
        self.take()
    }

    /// Skips the rest of the current line, including its line end.
    pub fn skip_line(&mut self) {
        while let Some(&b) = self.data.get(self.pos) {
            self.pos += 1;
            if b == b'\n' {
                self.line += 1;
                self.line_start = self.pos;
                return;
            }
        }
    }

    /// Skips blank lines and leading space; `false` at the end of the data.
    pub fn skip_blank(&mut self) -> bool {
        self.skip_space(false);
        self.pos < self.data.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_track_lines_and_columns() {
        let data = b"ab  cd\r\n\n  ef\tg";
        let mut t = Tokens::new(data, 0, 1);
        let a = t.next_on_line().unwrap();
        assert_eq!((a.bytes, a.loc.line, a.loc.column), (&b"ab"[..], 1, 1));
        let c = t.next_on_line().unwrap();
        assert_eq!((c.bytes, c.loc.column), (&b"cd"[..], 5));
        assert!(t.next_on_line().is_none());
        let e = t.next_token().unwrap();
        assert_eq!((e.bytes, e.loc.line, e.loc.column), (&b"ef"[..], 3, 3));
        t.skip_line();
        assert!(t.next_token().is_none());
        assert!(!t.skip_blank());
    }
}
