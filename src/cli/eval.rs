//! `fireflies eval`: estimators over a user's own dumped pixel samples.
//!
//! Output is one JSON object per estimator per line, in the order the estimators were given:
//! `{"estimator": <spec as given>, "n": <count>, "estimate": <f64>, <extras>...}`.
//! This format is documented in the README and kept stable.

use clap::Args;
use fireflies::estimators::{Estimator, EstimatorSpec, Extras, Zirr, ZirrRef};
use fireflies::{Error, Result, samples};
use std::fs::File;
use std::io::{self, BufReader, Write};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Estimator spec string, e.g. `gmon:M=21`; repeat for several.
    #[arg(long = "estimator", short = 'e', required = true, value_name = "SPEC")]
    estimators: Vec<String>,
    /// Nine files (row-major 3x3 block) for Zirr's neighbourhood variants; the centre is the
    /// fifth, an empty file is a pixel outside the image. Other estimators see the centre only.
    #[arg(long, num_args = 9, value_name = "FILE", conflicts_with = "file")]
    block: Option<Vec<PathBuf>>,
    /// Sample file: decimal numbers separated by whitespace or newlines; `-` or none = stdin.
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

/// Streams a file (or stdin for `-` or no file) block by block; returns the sample count.
fn stream(path: Option<&PathBuf>, mut on_block: impl FnMut(&[f64])) -> Result<u64> {
    let push = |block: &[f64]| {
        on_block(block);
        Ok(())
    };
    match path {
        Some(p) if p.as_os_str() != "-" => {
            let name = p.display().to_string();
            let file = File::open(p).map_err(|e| Error::io(&name, &e))?;
            samples::for_each_block(&name, BufReader::new(file), push)
        }
        _ => samples::for_each_block("-", io::stdin().lock(), push),
    }
}

pub fn run(args: &EvalArgs) -> Result<ExitCode> {
    let specs = parse_specs(&args.estimators)?;
    let lines = match &args.block {
        None => eval_stream(args.file.as_ref(), &args.estimators, &specs)?,
        Some(files) => eval_block(files, &args.estimators, &specs)?,
    };
    let mut out = io::stdout().lock();
    for line in lines {
        writeln!(out, "{line}").map_err(|e| Error::io("stdout", &e))?;
    }
    Ok(ExitCode::SUCCESS)
}

fn eval_stream(
    file: Option<&PathBuf>,
    texts: &[String],
    specs: &[EstimatorSpec],
) -> Result<Vec<String>> {
    let mut estimators = specs
        .iter()
        .map(EstimatorSpec::build)
        .collect::<Result<Vec<_>>>()?;
    let n = stream(file, |block| {
        estimators.iter_mut().for_each(|e| e.push_slice(block));
    })?;
    if n == 0 {
        let name = file.map_or("-".to_string(), |p| p.display().to_string());
        return Err(Error::EmptyStream(format!("input {name}")));
    }
    estimators
        .iter()
        .zip(texts)
        .map(|(e, text)| Ok(json_line(text, e.count(), e.estimate()?, &e.extras())))
        .collect()
}

/// Streams one named file into an estimator; returns the sample count.
fn read_into<T: Estimator + ?Sized>(estimator: &mut T, path: &PathBuf) -> Result<u64> {
    stream(Some(path), |block| estimator.push_slice(block))
}

/// The block estimate of a neighbourhood-capable estimator over nine files.
type BlockFn<T> = fn(&[Option<&T>; 9]) -> Result<(f64, Extras)>;

fn block_line<T: Estimator>(
    text: &str,
    files: &[PathBuf],
    build: impl Fn() -> Result<T>,
    block_estimate: BlockFn<T>,
) -> Result<String> {
    let mut pixels = Vec::with_capacity(9);
    for f in files {
        let mut e = build()?;
        let n = read_into(&mut e, f)?;
        pixels.push((n > 0).then_some(e));
    }
    let Some(centre) = &pixels[4] else {
        return Err(Error::EmptyStream(format!(
            "centre pixel {}",
            files[4].display()
        )));
    };
    let block: [Option<&T>; 9] = std::array::from_fn(|i| pixels[i].as_ref());
    let (estimate, extras) = block_estimate(&block)?;
    Ok(json_line(text, centre.count(), estimate, &extras))
}

fn eval_block(files: &[PathBuf], texts: &[String], specs: &[EstimatorSpec]) -> Result<Vec<String>> {
    let centre = &files[4];
    specs
        .iter()
        .zip(texts)
        .map(|(spec, text)| match *spec {
            EstimatorSpec::Zirr(p) => {
                block_line(text, files, || Zirr::new(p), Zirr::block_estimate)
            }
            EstimatorSpec::ZirrRef(p) => {
                block_line(text, files, || ZirrRef::new(p), ZirrRef::block_estimate)
            }
            _ => {
                let mut e = spec.build()?;
                if read_into(&mut *e, centre)? == 0 {
                    return Err(Error::EmptyStream(format!(
                        "centre pixel {}",
                        centre.display()
                    )));
                }
                Ok(json_line(text, e.count(), e.estimate()?, &e.extras()))
            }
        })
        .collect()
}
