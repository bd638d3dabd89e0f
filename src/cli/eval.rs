//! `fireflies eval`: estimators over a user's own dumped pixel samples.
//!
//! Output is one JSON object per estimator per line, in the order the estimators were given:
//! `{"estimator": <spec as given>, "n": <count>, "estimate": <f64>, <extras>...}`.
//! This format is documented in the README and kept stable.

use clap::Args;
use fireflies::estimators::{Estimator, EstimatorSpec, Extras, Zirr, ZirrRefSpec, ZirrSpec};
use fireflies::{Error, Result, samples};
use std::fs::File;
use std::io::{self, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Estimator spec string, e.g. `gmon:M=21`; repeat for several.
    #[arg(long = "estimator", short = 'e', required = true, value_name = "SPEC")]
    estimators: Vec<String>,
    /// Nine files (row-major 3x3 block) for Zirr's neighbourhood variants; the centre is the
    /// fifth, an empty file is a pixel outside the image. Other estimators see the centre only.
    /// Every file is read once, even when it fills several slots (`-`, stdin, included).
    #[arg(long, num_args = 9, value_name = "FILE", conflicts_with = "file")]
    block: Option<Vec<PathBuf>>,
    /// Sample file: decimal numbers separated by whitespace or newlines; `-` or none = stdin.
    /// UTF-8 text (a leading byte-order mark is skipped), tokens of at most 1024 bytes.
    file: Option<PathBuf>,
}

/// One estimator's result as a JSON line.
fn json_line(spec_text: &str, n: u64, estimate: f64, extras: &Extras) -> String {
    let mut obj = serde_json::Map::new();
    obj.insert("estimator".into(), spec_text.into());
    obj.insert("n".into(), n.into());
    obj.insert("estimate".into(), serde_json::json!(estimate));
    for (key, value) in extras {
        // Extras never replace the three fixed keys.
        let key = match *key {
            "estimator" | "n" | "estimate" => format!("extra_{key}"),
            k => k.to_string(),
        };
        obj.insert(key, serde_json::to_value(value).unwrap_or_default());
    }
    serde_json::Value::Object(obj).to_string()
}

fn parse_specs(texts: &[String]) -> Result<Vec<EstimatorSpec>> {
    texts.iter().map(|t| t.parse()).collect()
}

/// Where samples come from: standard input (`-` or no file) or a named file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Input<'a> {
    Stdin,
    File(&'a Path),
}

impl<'a> Input<'a> {
    pub(super) fn new(path: Option<&'a PathBuf>) -> Self {
        match path {
            Some(p) if p.as_os_str() != "-" => Input::File(p),
            _ => Input::Stdin,
        }
    }

    /// The name in messages, control characters escaped.
    pub(super) fn name(self) -> String {
        match self {
            Input::Stdin => "-".to_string(),
            Input::File(p) => samples::visible(&p.display().to_string()),
        }
    }

    /// Streams the input once, block by block; returns the sample count.
    pub(super) fn stream(self, mut on_block: impl FnMut(&[f64])) -> Result<u64> {
        let name = self.name();
        let push = |block: &[f64]| {
            on_block(block);
            Ok(())
        };
        match self {
            Input::File(p) => {
                let file = File::open(p).map_err(|e| Error::io(&name, &e))?;
                samples::for_each_block(&name, BufReader::new(file), push)
            }
            Input::Stdin => samples::for_each_block(&name, io::stdin().lock(), push),
        }
    }
}

/// What one `--estimator` reads: the centre slot only, or (Zirr's block estimates) every slot.
enum Job {
    Centre(Box<dyn Estimator>),
    Zirr(Vec<Zirr>),
}

impl Job {
    /// The job of `spec` over `slots` slots; Zirr's estimators read every slot in block mode.
    fn new(spec: &EstimatorSpec, slots: usize, block_mode: bool) -> Result<Job> {
        Ok(match *spec {
            EstimatorSpec::Zirr(ZirrSpec(p)) if block_mode => {
                Job::Zirr((0..slots).map(|_| Zirr::new(p)).collect::<Result<_>>()?)
            }
            EstimatorSpec::ZirrRef(ZirrRefSpec(p)) if block_mode => Job::Zirr(
                (0..slots)
                    .map(|_| Zirr::reference(p))
                    .collect::<Result<_>>()?,
            ),
            _ => Job::Centre(spec.build()?),
        })
    }

    /// Feeds a block of the input named by the slots `at`.
    fn push(&mut self, at: &[usize], centre: usize, block: &[f64]) {
        match self {
            Job::Centre(e) => {
                if at.contains(&centre) {
                    e.push_slice(block);
                }
            }
            Job::Zirr(pixels) => at.iter().for_each(|&i| pixels[i].push_slice(block)),
        }
    }

    /// The JSON line; `counts` holds each slot's sample count (0: a pixel outside the image).
    fn line(&self, text: &str, counts: &[u64], centre: usize) -> Result<String> {
        match self {
            Job::Centre(e) => Ok(json_line(text, e.count(), e.estimate()?, &e.extras())),
            Job::Zirr(pixels) => block_line(text, pixels, counts, centre, Zirr::block_estimate),
        }
    }
}

/// The block estimate of a neighbourhood-capable estimator over nine pixels.
type BlockFn<T> = fn(&[Option<&T>; 9]) -> Result<(f64, Extras)>;

fn block_line<T: Estimator>(
    text: &str,
    pixels: &[T],
    counts: &[u64],
    centre: usize,
    block_estimate: BlockFn<T>,
) -> Result<String> {
    let block: [Option<&T>; 9] = std::array::from_fn(|i| (counts[i] > 0).then(|| &pixels[i]));
    let (estimate, extras) = block_estimate(&block)?;
    Ok(json_line(text, pixels[centre].count(), estimate, &extras))
}

pub fn run(args: &EvalArgs) -> Result<ExitCode> {
    let specs = parse_specs(&args.estimators)?;
    let lines = match &args.block {
        None => eval(
            &[Input::new(args.file.as_ref())],
            0,
            &args.estimators,
            &specs,
        )?,
        Some(files) => {
            let slots: Vec<Input> = files.iter().map(|f| Input::new(Some(f))).collect();
            eval(&slots, 4, &args.estimators, &specs)?
        }
    };
    let mut out = io::stdout().lock();
    for line in lines {
        writeln!(out, "{line}").map_err(|e| Error::io("stdout", &e))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Evaluates every spec over `slots` (one input, or nine in block mode with the centre at
/// `centre`). Each distinct input is read exactly once, in order of first appearance, and each
/// block of it is fed to every estimator of every slot naming it; so repeated specs give
/// identical lines, and standard input may fill several slots.
fn eval(
    slots: &[Input],
    centre: usize,
    texts: &[String],
    specs: &[EstimatorSpec],
) -> Result<Vec<String>> {
    let block_mode = slots.len() > 1;
    let mut jobs = specs
        .iter()
        .map(|spec| Job::new(spec, slots.len(), block_mode))
        .collect::<Result<Vec<_>>>()?;
    let mut distinct: Vec<(Input, Vec<usize>)> = Vec::new();
    for (i, &input) in slots.iter().enumerate() {
        match distinct.iter_mut().find(|(seen, _)| *seen == input) {
            Some((_, at)) => at.push(i),
            None => distinct.push((input, vec![i])),
        }
    }
    let mut counts = vec![0u64; slots.len()];
    for (input, at) in &distinct {
        let n = input.stream(|block| {
            jobs.iter_mut().for_each(|job| job.push(at, centre, block));
        })?;
        at.iter().for_each(|&i| counts[i] = n);
    }
    if counts[centre] == 0 {
        let what = if block_mode { "centre pixel" } else { "input" };
        let name = slots[centre].name();
        return Err(Error::EmptyStream(format!("{what} {name}")));
    }
    jobs.iter()
        .zip(texts)
        .map(|(job, text)| job.line(text, &counts, centre))
        .collect()
}
