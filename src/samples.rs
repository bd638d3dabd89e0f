//! Sample streams as text: whitespace- or newline-separated decimal numbers, the format a
//! renderer's per-pixel dump is easiest to write.
//!
//! The reader holds a fixed amount of memory whatever the input — one block of [`BLOCK`]
//! samples and one token of at most [`MAX_TOKEN_BYTES`] bytes, besides the `BufRead`'s own
//! buffer — so a file of any length, a single line of any length, or an endless stream such as
//! `/dev/zero` is evaluated in constant memory and any error arrives after at most
//! [`MAX_TOKEN_BYTES`] bytes of a token.
//!
//! The text must be UTF-8. Separators are the Unicode whitespace characters (`char::is_whitespace`:
//! space, tab, CR, LF, vertical tab, form feed, NEL, no-break space, ...); lines end at LF only.
//! A byte-order mark (`U+FEFF`) as the very first character is skipped, as editors on Windows
//! write one; anywhere else it is part of a token, which is then malformed.
//!
//! Every error is an [`Error::SampleText`] naming the file, line and column (1-based, counted in
//! characters) of the offending token or byte: a token that is not a decimal number, a token
//! longer than [`MAX_TOKEN_BYTES`], a NUL byte (a binary file, or `/dev/zero`), invalid UTF-8,
//! or a number that is not a valid sample (NaN, infinite or negative). Messages quote at most
//! [`QUOTE_CHARS`] characters of input, ending a longer quote with `…` and the token's length,
//! and show control and other invisible characters escaped as Rust does (`\0`, `\t`,
//! `\u{feff}`); invalid UTF-8 is shown as its bytes (`\xff`).

use crate::error::{Error, Num, Result};
use std::io::{BufRead, ErrorKind};

/// Samples handed to the callback at a time.
pub const BLOCK: usize = 4096;

/// The longest token accepted, in bytes; a longer one is an error as soon as its byte
/// `MAX_TOKEN_BYTES + 1` arrives, so that a stream with no separators (a binary blob, an endless
/// run of digits) fails after a bounded read instead of being buffered whole. Any `f64`
/// round-trips through 17 significant digits (24 characters with sign and exponent), and even
/// the largest written out in full as an integer has 309 digits; only an exact fixed-point
/// expansion of a value below about 1e-295 (`%.1100f`) would be longer.
pub const MAX_TOKEN_BYTES: usize = 1024;

/// The most characters of input an error message quotes (after escaping).
pub const QUOTE_CHARS: usize = 40;

/// Appends `c` as it should appear in a message: as itself when printable, escaped the way Rust
/// escapes it in debug output otherwise (`\0`, `\n`, `\u{feff}`, and `\\`, `\'` so that an
/// escape in the output is never ambiguous). Double quotes are left alone.
fn push_visible(c: char, out: &mut String) {
    if c == '"' {
        out.push(c);
    } else {
        out.extend(c.escape_debug());
    }
}

/// `text` with its control and other invisible characters escaped as Rust's debug output
/// escapes them (`\0`, `\n`, `\u{feff}`, and `\\`, `\'`), double quotes left alone; for file
/// names and other text put in messages whole.
pub fn visible(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    text.chars().for_each(|c| push_visible(c, &mut out));
    out
}

/// `text` quoted for a message, `'...'`, escaped and cut to at most [`QUOTE_CHARS`] characters
/// after escaping; a cut quote ends with `…` and is followed by the token's `length`.
fn quote(text: &str, length: impl std::fmt::Display) -> String {
    let mut out = String::from("'");
    let mut shown = 0;
    let mut escaped = String::new();
    for c in text.chars() {
        escaped.clear();
        push_visible(c, &mut escaped);
        let width = escaped.chars().count();
        if shown + width > QUOTE_CHARS {
            return format!("{out}…' ({length})");
        }
        out.push_str(&escaped);
        shown += width;
    }
    out.push('\'');
    out
}

/// The byte-level state of a sample stream: position, the token being read and a partial UTF-8
/// sequence. Fixed capacity: the token never holds more than [`MAX_TOKEN_BYTES`] bytes.
struct Lexer {
    name: String,
    /// 1-based line of the next character.
    line: usize,
    /// 1-based column of the next character, in characters.
    column: usize,
    /// True until the first character: where a byte-order mark is skipped.
    at_start: bool,
    token: Vec<u8>,
    /// Line and column of the token's first character.
    token_at: (usize, usize),
    /// The UTF-8 sequence being decoded, its length so far and its full length (0: none).
    utf8: [u8; 4],
    utf8_len: usize,
    utf8_need: usize,
    /// Samples accepted so far.
    index: u64,
}

impl Lexer {
    fn new(name: String) -> Self {
        Lexer {
            name,
            line: 1,
            column: 1,
            at_start: true,
            token: Vec::with_capacity(MAX_TOKEN_BYTES),
            token_at: (1, 1),
            utf8: [0; 4],
            utf8_len: 0,
            utf8_need: 0,
            index: 0,
        }
    }

    fn error(&self, (line, column): (usize, usize), problem: String) -> Error {
        Error::SampleText {
            file: self.name.clone(),
            line,
            column,
            problem,
        }
    }

    /// The error for the bytes of a UTF-8 sequence that is not valid, at the next character.
    fn invalid_utf8(&self, bytes: &[u8]) -> Error {
        let shown: String = bytes.iter().map(|b| format!("\\x{b:02x}")).collect();
        self.error(
            (self.line, self.column),
            format!("invalid UTF-8 '{shown}': sample files are text"),
        )
    }

    /// Takes bytes from the start of `buf` until it is used up or `block` holds [`BLOCK`]
    /// samples; returns how many were taken. The same as [`Lexer::byte`] on each, with a fast
    /// path for the common case of printable ASCII and ASCII separators.
    fn bytes(&mut self, buf: &[u8], block: &mut Vec<f64>) -> Result<usize> {
        let printable = |b: &u8| (b'!'..=b'~').contains(b);
        let mut i = 0;
        while i < buf.len() && block.len() < BLOCK {
            let b = buf[i];
            // The slow path decodes UTF-8 and handles the start of the stream (the BOM).
            if self.utf8_need == 0 && !self.at_start {
                if printable(&b) {
                    let run = buf[i..].iter().position(|b| !printable(b));
                    let run = run.unwrap_or(buf.len() - i);
                    // Up to the limit; a byte over it goes the slow way, which reports it.
                    let take = run.min(MAX_TOKEN_BYTES - self.token.len());
                    if take > 0 {
                        if self.token.is_empty() {
                            self.token_at = (self.line, self.column);
                        }
                        self.token.extend_from_slice(&buf[i..i + take]);
                        self.column += take;
                        i += take;
                        continue;
                    }
                } else if matches!(b, b' ' | b'\t' | b'\r' | 0x0b | 0x0c) {
                    self.end_token(block)?;
                    self.column += 1;
                    i += 1;
                    continue;
                } else if b == b'\n' {
                    self.end_token(block)?;
                    self.line += 1;
                    self.column = 1;
                    i += 1;
                    continue;
                }
            }
            self.byte(b, block)?;
            i += 1;
        }
        Ok(i)
    }

    /// Takes one byte; a finished sample goes to `block`, which must have room for one.
    fn byte(&mut self, b: u8, block: &mut Vec<f64>) -> Result<()> {
        if self.utf8_need > 0 {
            if b & 0xC0 != 0x80 {
                let mut bytes = self.utf8[..self.utf8_len].to_vec();
                bytes.push(b);
                return Err(self.invalid_utf8(&bytes));
            }
            self.utf8[self.utf8_len] = b;
            self.utf8_len += 1;
            if self.utf8_len < self.utf8_need {
                return Ok(());
            }
            let seq = self.utf8;
            let seq = &seq[..self.utf8_need];
            self.utf8_need = 0;
            // The lead byte fixed the length; this rejects overlong forms and surrogates.
            return match std::str::from_utf8(seq).ok().and_then(|s| s.chars().next()) {
                Some(c) => self.char(c, seq, block),
                None => Err(self.invalid_utf8(seq)),
            };
        }
        if b.is_ascii() {
            return self.char(char::from(b), &[b], block);
        }
        self.utf8_need = match b {
            0xC2..=0xDF => 2,
            0xE0..=0xEF => 3,
            0xF0..=0xF4 => 4,
            _ => return Err(self.invalid_utf8(&[b])),
        };
        self.utf8[0] = b;
        self.utf8_len = 1;
        Ok(())
    }

    /// Takes one decoded character, `bytes` its UTF-8 encoding.
    fn char(&mut self, c: char, bytes: &[u8], block: &mut Vec<f64>) -> Result<()> {
        let at_start = std::mem::replace(&mut self.at_start, false);
        if c == '\n' {
            self.end_token(block)?;
            self.line += 1;
            self.column = 1;
        } else if c == '\u{feff}' && at_start {
            // A byte-order mark: invisible in editors, so it takes no column.
        } else if c == '\0' {
            return Err(self.error(
                (self.line, self.column),
                "NUL byte '\\0': sample files are text".to_string(),
            ));
        } else if c.is_whitespace() {
            self.end_token(block)?;
            self.column += 1;
        } else {
            if self.token.is_empty() {
                self.token_at = (self.line, self.column);
            }
            if self.token.len() + bytes.len() > MAX_TOKEN_BYTES {
                // The token so far is valid UTF-8 and longer than any quote.
                let text = std::str::from_utf8(&self.token).unwrap_or("");
                let problem = format!(
                    "token longer than the limit of {MAX_TOKEN_BYTES} bytes: {}",
                    quote(text, format_args!("more than {MAX_TOKEN_BYTES} bytes"))
                );
                return Err(self.error(self.token_at, problem));
            }
            self.token.extend_from_slice(bytes);
            self.column += 1;
        }
        Ok(())
    }

    /// Parses the token read so far, if any, into `block`.
    fn end_token(&mut self, block: &mut Vec<f64>) -> Result<()> {
        if self.token.is_empty() {
            return Ok(());
        }
        // The token is valid UTF-8: it was built from decoded characters.
        let text = std::str::from_utf8(&self.token).unwrap_or("");
        let Ok(value) = text.parse::<f64>() else {
            let length = format!("{} bytes", self.token.len());
            let problem = format!("malformed number {}", quote(text, length));
            return Err(self.error(self.token_at, problem));
        };
        if !(value >= 0.0 && value.is_finite()) {
            let problem = format!("invalid sample at index {}: {}", self.index, Num(value));
            return Err(self.error(self.token_at, problem));
        }
        block.push(value);
        self.index += 1;
        self.token.clear();
        Ok(())
    }

    /// Ends the stream: a partial UTF-8 sequence is an error, a last token is parsed.
    fn finish(&mut self, block: &mut Vec<f64>) -> Result<()> {
        if self.utf8_need > 0 {
            let bytes = self.utf8[..self.utf8_len].to_vec();
            self.utf8_need = 0;
            return Err(self.invalid_utf8(&bytes));
        }
        self.end_token(block)
    }
}

/// A text sample stream read in blocks of at most [`BLOCK`] samples, in constant memory (see the
/// module docs for the format, the limits and the errors).
///
/// # Examples
///
/// ```
/// use fireflies::samples::SampleReader;
///
/// let mut reader = SampleReader::new("pixel.txt", "0.6 1.5\n0 2.2".as_bytes());
/// assert_eq!(reader.next_block()?, Some(&[0.6, 1.5, 0.0, 2.2][..]));
/// assert_eq!(reader.next_block()?, None);
///
/// let mut reader = SampleReader::new("pixel.txt", "1\n2 x3\n".as_bytes());
/// let e = reader.next_block().unwrap_err();
/// assert_eq!(e.to_string(), "pixel.txt:2: malformed number 'x3' (column 3)");
/// # Ok::<(), fireflies::Error>(())
/// ```
pub struct SampleReader<R> {
    reader: R,
    lexer: Lexer,
    block: Vec<f64>,
    done: bool,
}

impl<R: BufRead> SampleReader<R> {
    /// A reader of `reader`, named `name` in errors (`-` for stdin by convention). `name` is
    /// used as given: pass it through [`visible`] if it may hold control characters.
    pub fn new(name: impl Into<String>, reader: R) -> Self {
        SampleReader {
            reader,
            lexer: Lexer::new(name.into()),
            block: Vec::with_capacity(BLOCK),
            done: false,
        }
    }

    /// The next block of at most [`BLOCK`] samples in stream order, or `None` at the end.
    ///
    /// # Errors
    ///
    /// [`Error::SampleText`] for text that is not a valid sample stream, naming the file, line
    /// and column; [`Error::Io`] when reading fails. After an error the stream is left where the
    /// error was found, and the reader should be dropped.
    pub fn next_block(&mut self) -> Result<Option<&[f64]>> {
        self.block.clear();
        while !self.done && self.block.len() < BLOCK {
            let buf = match self.reader.fill_buf() {
                Ok(buf) => buf,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(Error::io(&self.lexer.name, &e)),
            };
            if buf.is_empty() {
                self.done = true;
                self.lexer.finish(&mut self.block)?;
                break;
            }
            let used = self.lexer.bytes(buf, &mut self.block)?;
            self.reader.consume(used);
        }
        Ok((!self.block.is_empty()).then_some(&self.block[..]))
    }

    /// Samples read so far.
    pub fn count(&self) -> u64 {
        self.lexer.index
    }

    /// Bytes of heap the reader itself holds (its sample block and token buffer), not counting
    /// the `BufRead`'s own buffer: the same from construction to the end of any input.
    pub fn heap_bytes(&self) -> usize {
        self.block.capacity() * size_of::<f64>() + self.lexer.token.capacity()
    }
}

/// Reads every sample of `reader` (named `name` in errors) and hands them on in blocks of at
/// most [`BLOCK`], in order. Returns the number of samples read.
///
/// # Errors
///
/// As [`SampleReader::next_block`], and any error of `on_block`.
pub fn for_each_block(
    name: &str,
    reader: impl BufRead,
    mut on_block: impl FnMut(&[f64]) -> Result<()>,
) -> Result<u64> {
    let mut samples = SampleReader::new(name, reader);
    while let Some(block) = samples.next_block()? {
        on_block(block)?;
    }
    Ok(samples.count())
}

/// Reads a whole stream into memory.
///
/// # Errors
///
/// As [`for_each_block`].
pub fn read_all(name: &str, reader: impl BufRead) -> Result<Vec<f64>> {
    let mut all = Vec::new();
    for_each_block(name, reader, |b| {
        all.extend_from_slice(b);
        Ok(())
    })?;
    Ok(all)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{BufReader, Read};

    fn error_of(text: &[u8]) -> String {
        read_all("f", text).unwrap_err().to_string()
    }

    #[test]
    fn reads_mixed_separators_and_names_bad_tokens() {
        let xs = read_all("a.txt", "0.6 1.5\n0\n\n 2.2\t4.8 3.5e2\n4.1".as_bytes()).unwrap();
        assert_eq!(xs, vec![0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1]);
        let e = read_all("a.txt", "1\n2 x3\n".as_bytes()).unwrap_err();
        assert_eq!(e.to_string(), "a.txt:2: malformed number 'x3' (column 3)");
        let e = read_all("-", "1\n2\n-3".as_bytes()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "-:3: invalid sample at index 2: -3 (column 1)"
        );
        let e = read_all("f", "1 nan".as_bytes()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "f:1: invalid sample at index 1: NaN (column 3)"
        );
    }

    #[test]
    fn invalid_samples_print_short_numbers() {
        assert_eq!(
            error_of(b"1 -1e300"),
            "f:1: invalid sample at index 1: -1e300 (column 3)"
        );
        assert_eq!(
            error_of(b"1e400"),
            "f:1: invalid sample at index 0: inf (column 1)"
        );
    }

    #[test]
    fn long_streams_arrive_in_ordered_blocks() {
        let text: String = (0..10_000).map(|i| format!("{i}\n")).collect();
        let mut seen = Vec::new();
        let n = for_each_block("t", text.as_bytes(), |b| {
            assert!(b.len() <= BLOCK);
            seen.extend_from_slice(b);
            Ok(())
        })
        .unwrap();
        assert_eq!(n, 10_000);
        assert!(seen.iter().enumerate().all(|(i, &x)| x == i as f64));
    }

    #[test]
    fn nul_bytes_are_errors_shown_visibly_with_their_position() {
        assert_eq!(
            error_of(b"\0\0\0"),
            "f:1: NUL byte '\\0': sample files are text (column 1)"
        );
        assert_eq!(
            error_of("1 2\n 3\u{e9}\0".as_bytes()),
            "f:2: NUL byte '\\0': sample files are text (column 4)"
        );
    }

    #[test]
    fn invalid_utf8_names_its_bytes_line_and_column() {
        assert_eq!(
            error_of(b"1\n2 \xff"),
            "f:2: invalid UTF-8 '\\xff': sample files are text (column 3)"
        );
        // A lead byte followed by a non-continuation byte, and a sequence cut by the end.
        assert_eq!(
            error_of(b"\xe2\x28"),
            "f:1: invalid UTF-8 '\\xe2\\x28': sample files are text (column 1)"
        );
        assert_eq!(
            error_of(b"1 \xe2\x82"),
            "f:1: invalid UTF-8 '\\xe2\\x82': sample files are text (column 3)"
        );
        // Overlong encodings and surrogates are not UTF-8 either.
        assert!(error_of(b"\xe0\x80\xb1").contains("invalid UTF-8 '\\xe0\\x80\\xb1'"));
        assert!(error_of(b"\xed\xa0\x80").contains("invalid UTF-8"));
    }

    #[test]
    fn a_leading_byte_order_mark_is_skipped_and_any_other_is_shown() {
        let xs = read_all("f", "\u{feff}1 2\n3".as_bytes()).unwrap();
        assert_eq!(xs, vec![1.0, 2.0, 3.0]);
        // Columns after a skipped mark count from the first visible character.
        assert_eq!(
            error_of("\u{feff}1 x".as_bytes()),
            "f:1: malformed number 'x' (column 3)"
        );
        assert_eq!(
            error_of("1 \u{feff}2".as_bytes()),
            "f:1: malformed number '\\u{feff}2' (column 3)"
        );
    }

    #[test]
    fn unicode_whitespace_separates_and_columns_count_characters() {
        let xs = read_all("f", "1\u{a0}2\u{2003}3\r\n4\u{b}5\u{c}6".as_bytes()).unwrap();
        assert_eq!(xs, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(
            error_of("\u{e9}\u{a0}y".as_bytes()),
            "f:1: malformed number '\u{e9}' (column 1)"
        );
        assert_eq!(
            error_of("1\u{a0}\u{e9}\u{e9} y".as_bytes()),
            "f:1: malformed number '\u{e9}\u{e9}' (column 3)"
        );
    }

    #[test]
    fn control_characters_in_tokens_are_escaped() {
        assert_eq!(
            error_of(b"1\x1b[31m2"),
            "f:1: malformed number '1\\u{1b}[31m2' (column 1)"
        );
        assert_eq!(
            error_of(b"1\x01\x7f'\\"),
            "f:1: malformed number '1\\u{1}\\u{7f}\\'\\\\' (column 1)"
        );
    }

    #[test]
    fn long_tokens_are_quoted_short_with_their_length() {
        let token = "7".repeat(MAX_TOKEN_BYTES - 1) + "x";
        let e = error_of(format!("1\n  {token} 2").as_bytes());
        let want = format!(
            "f:2: malformed number '{}…' ({MAX_TOKEN_BYTES} bytes) (column 3)",
            "7".repeat(QUOTE_CHARS)
        );
        assert_eq!(e, want);
        // A token of exactly QUOTE_CHARS characters is shown whole.
        let token = "y".repeat(QUOTE_CHARS);
        assert_eq!(
            error_of(token.as_bytes()),
            format!("f:1: malformed number '{token}' (column 1)")
        );
        // Escapes count towards the quote's length: no message grows with the input.
        let e = error_of(&[1u8; 500]);
        assert!(e.chars().count() < 120, "{e}");
    }

    #[test]
    fn a_token_over_the_limit_fails_at_its_start() {
        let ok = "0".repeat(MAX_TOKEN_BYTES - 1) + "1";
        assert_eq!(read_all("f", ok.as_bytes()).unwrap(), vec![1.0]);
        let e = error_of(format!("5\n 0{ok}").as_bytes());
        assert_eq!(
            e,
            format!(
                "f:2: token longer than the limit of {MAX_TOKEN_BYTES} bytes: '0{}…' \
                 (more than {MAX_TOKEN_BYTES} bytes) (column 2)",
                "0".repeat(QUOTE_CHARS - 1)
            )
        );
        // Multi-byte characters may not straddle the limit either.
        let e = error_of("\u{e9}".repeat(MAX_TOKEN_BYTES / 2 + 1).as_bytes());
        assert!(e.contains("token longer than the limit"), "{e}");
    }

    /// An endless stream of one byte, counting how much was read from it.
    struct Endless {
        byte: u8,
        read: usize,
    }

    impl Read for Endless {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            buf.fill(self.byte);
            self.read += buf.len();
            Ok(buf.len())
        }
    }

    #[test]
    fn endless_streams_fail_after_a_bounded_read_in_constant_memory() {
        for (byte, problem) in [(b'0', "token longer than the limit"), (0, "NUL byte")] {
            let mut source = BufReader::with_capacity(64, Endless { byte, read: 0 });
            let mut reader = SampleReader::new("endless", &mut source);
            let heap = reader.heap_bytes();
            assert_eq!(heap, BLOCK * 8 + MAX_TOKEN_BYTES);
            let e = reader.next_block().unwrap_err().to_string();
            assert!(e.contains(problem) && e.contains("(column 1)"), "{e}");
            assert!(e.chars().count() < 150, "{e}");
            assert_eq!(reader.heap_bytes(), heap);
            assert!(source.get_ref().read <= MAX_TOKEN_BYTES + 64);
        }
    }

    #[test]
    fn chunk_boundaries_do_not_change_the_result() {
        let text = "\u{feff}0.5 1e3\u{a0}2\n\u{2003}7 é".as_bytes();
        for capacity in 1..8 {
            let e = read_all("f", BufReader::with_capacity(capacity, text))
                .unwrap_err()
                .to_string();
            assert_eq!(e, "f:2: malformed number 'é' (column 4)", "{capacity}");
            let xs = read_all("f", BufReader::with_capacity(capacity, &text[..18])).unwrap();
            assert_eq!(xs, vec![0.5, 1e3, 2.0, 7.0], "{capacity}");
        }
    }
}
