//! Fuzzing of `fireflies eval`'s input path (issue 10): arbitrary bytes — and bytes biased
//! towards the corners of the format (digits, signs, exponents, separators, NUL, a byte-order
//! mark, stray UTF-8 lead and continuation bytes) — never panic, never grow memory, and end in
//! samples or in an error naming a position.
//!
//! The library's sample reader is fuzzed in-process, with the estimators `eval` runs fed from
//! it; a few inputs go through the binary itself, whose exit status must be 0, 1 or 2 (a panic
//! would be 101).

use fireflies::EstimatorSpec;
use fireflies::samples::{self, BLOCK, MAX_TOKEN_BYTES, QUOTE_CHARS, SampleReader};
use fireflies::{Error, Result};
use proptest::prelude::*;
use proptest::test_runner::Config;
use std::io::{BufReader, Write};
use std::process::{Command, Stdio};

/// In-process cases per property: each reads a few hundred bytes, so this runs in well under a
/// second in release.
const CASES: u32 = 512;

/// Cases through the binary: each starts a process, so few.
const BINARY_CASES: u32 = 24;

/// The specs `eval` is fuzzed with: one of each kind of estimator.
const SPECS: [&str; 6] = [
    "mean",
    "gmon:M=5",
    "jung:sigma_image=1",
    "zirr",
    "zirr-ref",
    "pajot-hybrid",
];

/// Text that is mostly a valid sample stream — numbers written in the ways `str::parse`
/// accepts, between runs of ASCII and Unicode separators — with now and then a token that is
/// malformed, negative or infinite (about half of the streams have none).
fn sample_text() -> impl Strategy<Value = String> {
    let number = prop_oneof![
        (0u32..100_000).prop_map(|n| n.to_string()),
        (0.0f64..1e6).prop_map(|x| x.to_string()),
        (0.0f64..1e300).prop_map(|x| format!("{x:e}")),
        (0u32..1000).prop_map(|n| format!("+.{n}E-3")),
        Just("-0".to_string()),
    ];
    let junk = proptest::sample::select(
        &[
            ".", "e", "-1", "inf", "nan", "1e400", "x", "\u{e9}", "1\u{1b}", "1e", "--1",
        ][..],
    );
    let token = prop_oneof![80 => number, 1 => junk.prop_map(String::from)];
    let separator = proptest::sample::select(
        &[
            " ", "\n", "\t", "\r\n", "\u{b}", "\u{c}", "\u{85}", "\u{a0}", "\u{2003}",
        ][..],
    );
    let separators = proptest::collection::vec(separator, 1..3).prop_map(|s| s.concat());
    proptest::collection::vec((token, separators), 0..100)
        .prop_map(|pairs| pairs.into_iter().map(|(t, s)| t + &s).collect())
}

/// Sample text with a few hazards spliced in at arbitrary byte positions (possibly inside a
/// multi-byte character): NUL, a byte-order mark, invalid or partial UTF-8.
fn tricky_bytes() -> impl Strategy<Value = Vec<u8>> {
    let hazard = proptest::sample::select(vec![
        vec![0],
        vec![0xff],
        vec![0xc3],
        vec![0xa9],
        vec![0xe2, 0x82],
        vec![0xed, 0xa0, 0x80],
        vec![0xe0, 0x80, 0xb1],
        vec![0xf0, 0x9f, 0x98, 0x80],
        "\u{feff}".as_bytes().to_vec(),
    ]);
    let hazards = proptest::collection::vec((any::<prop::sample::Index>(), hazard), 0..2);
    (sample_text(), hazards).prop_map(|(text, hazards)| {
        let mut bytes = text.into_bytes();
        for (at, hazard) in hazards {
            let at = at.index(bytes.len() + 1);
            bytes.splice(at..at, hazard);
        }
        bytes
    })
}

/// Arbitrary bytes, or (more often, as they reach further into the format) tricky ones.
fn input() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        1 => proptest::collection::vec(any::<u8>(), 0..400),
        3 => tricky_bytes(),
    ]
}

/// What `eval` does with one input, through the library: read every block into each estimator,
/// then estimate. Returns the exit code `eval` would give (0, or 2 for an error) and the text.
fn eval_in_process(bytes: &[u8], capacity: usize) -> (u8, String) {
    let run = || -> Result<String> {
        let mut estimators = SPECS
            .iter()
            .map(|s| s.parse::<EstimatorSpec>()?.build())
            .collect::<Result<Vec<_>>>()?;
        let mut reader = SampleReader::new("fuzz", BufReader::with_capacity(capacity, bytes));
        let heap = reader.heap_bytes();
        while let Some(block) = reader.next_block()? {
            assert!(block.len() <= BLOCK);
            assert!(
                block.iter().all(|x| x.is_finite() && *x >= 0.0),
                "{block:?}"
            );
            estimators.iter_mut().for_each(|e| e.push_slice(block));
        }
        assert_eq!(reader.heap_bytes(), heap, "the reader's buffers never grow");
        if reader.count() == 0 {
            return Err(Error::EmptyStream("input fuzz".into()));
        }
        let mut text = String::new();
        for e in &estimators {
            assert_eq!(e.count(), reader.count());
            text.push_str(&format!("{} {}\n", e, e.estimate()?));
        }
        Ok(text)
    };
    match run() {
        Ok(text) => (0, text),
        Err(e) => (2, e.to_string()),
    }
}

/// The invariants of an error message: a position, no raw control character, and a bounded
/// quote of the input whatever its length.
fn check_error(message: &str) {
    assert!(!message.chars().any(char::is_control), "{message:?}");
    assert!(
        message.chars().count() < 2 * QUOTE_CHARS + 100,
        "too long: {message}"
    );
    if !message.starts_with("empty stream") {
        assert!(message.starts_with("fuzz:"), "{message}");
        assert!(message.contains("(column "), "{message}");
    }
}

fn config(cases: u32) -> Config {
    Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    }
}

proptest! {
    #![proptest_config(config(CASES))]

    /// Any input ends in samples or in a positioned error, the same however the bytes are
    /// split into reads (multi-byte characters and tokens straddle buffer boundaries).
    #[test]
    fn eval_never_panics_and_ignores_read_boundaries(bytes in input(), capacity in 1usize..64) {
        let (code, text) = eval_in_process(&bytes, 8192);
        prop_assert!(code == 0 || code == 2);
        if code == 2 {
            check_error(&text);
        }
        prop_assert_eq!((code, text), eval_in_process(&bytes, capacity));
    }

    /// On text without NUL, byte-order mark or over-long token, the reader agrees with the
    /// plain reading of the format: `split_whitespace` and `str::parse`; a malformed, negative
    /// or infinite token is an error in both.
    #[test]
    fn valid_text_reads_as_split_whitespace_does(text in sample_text()) {
        let plain: std::result::Result<Vec<f64>, ()> = text
            .split_whitespace()
            .map(|t| match t.parse::<f64>() {
                Ok(x) if x >= 0.0 && x.is_finite() => Ok(x),
                _ => Err(()),
            })
            .collect();
        let read = samples::read_all("fuzz", text.as_bytes());
        match (plain, read) {
            (Ok(want), Ok(got)) => prop_assert_eq!(want, got),
            (Err(()), Err(e)) => prop_assert!(matches!(e, Error::SampleText { .. }), "{}", e),
            (want, got) => prop_assert!(false, "plain {:?}, reader {:?}", want, got),
        }
    }

    /// A run without separators fails at its start once it passes the limit, whatever follows.
    #[test]
    fn an_over_long_token_fails_at_its_start(prefix in "[0-9 \n]{0,20}", extra in 1usize..64) {
        let token = "7".repeat(MAX_TOKEN_BYTES + extra);
        let text = format!("{prefix} {token}\n1");
        let e = samples::read_all("fuzz", text.as_bytes()).unwrap_err();
        let line = 1 + prefix.matches('\n').count();
        let column = 2 + prefix.len() - prefix.rfind('\n').map_or(0, |i| i + 1);
        let msg = e.to_string();
        let at = format!("fuzz:{line}: token longer than the limit");
        prop_assert!(msg.starts_with(&at), "{}", msg);
        prop_assert!(msg.ends_with(&format!("(column {column})")), "{}", msg);
    }
}

/// Runs the binary on `args` with `bytes` on standard input; returns its exit code, stdout and
/// stderr.
fn run_binary(args: &[&str], bytes: &[u8]) -> (Option<i32>, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_fireflies"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    // The child stops reading at its first error: a broken pipe is expected then.
    let _ = stdin.write_all(bytes);
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    (out.status.code(), text(&out.stdout), text(&out.stderr))
}

proptest! {
    #![proptest_config(config(BINARY_CASES))]

    /// Through the binary, on stdin alone and on stdin filling every slot of a block: exit 0
    /// with one line per estimator, repeated specs giving identical lines, or exit 2 with a
    /// message free of raw control characters.
    #[test]
    fn the_binary_exits_0_or_2_on_any_input(bytes in input(), block in any::<bool>()) {
        let mut args = vec!["eval", "-e", "zirr-ref", "-e", "mean", "-e", "zirr-ref"];
        if block {
            args.push("--block");
            args.extend(["-"; 9]);
        }
        let (code, stdout, stderr) = run_binary(&args, &bytes);
        prop_assert!(matches!(code, Some(0..=2)), "exit {:?}: {}", code, stderr);
        if code == Some(0) {
            let lines: Vec<&str> = stdout.lines().collect();
            prop_assert_eq!(lines.len(), 3);
            prop_assert_eq!(lines[0], lines[2]);
        } else {
            prop_assert!(stderr.starts_with("error: "), "{}", stderr);
            prop_assert!(!stderr.trim_end().chars().any(char::is_control), "{:?}", stderr);
        }
    }
}
