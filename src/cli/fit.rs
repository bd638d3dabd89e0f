//! `fireflies fit`: a generator fitted to one pixel's luminance stream (the model is documented
//! in `fireflies::dist::fit`), printed as one JSON object on stdout, with the spec an experiment
//! file can use, and optionally a tail QQ plot.

use super::eval::Input;
use clap::Args;
use fireflies::dist::fit::{Component, Detail, Fit, Role, fit};
use fireflies::report::qq::write_tail_qq;
use fireflies::{Error, Result};
use serde_json::{Map, Value, json};
use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct FitArgs {
    /// Sample file, as `fireflies eval` reads it: decimal numbers separated by whitespace or
    /// newlines; `-` or none = stdin.
    file: Option<PathBuf>,
    /// Also draw the tail QQ plot (PNG) into this file.
    #[arg(long, value_name = "FILE.png")]
    qq: Option<PathBuf>,
    /// Label of the distribution in the `toml` snippet (default: the file's stem, or `fitted`
    /// for stdin).
    #[arg(long)]
    label: Option<String>,
}

pub fn run(args: &FitArgs) -> Result<ExitCode> {
    let input = Input::new(args.file.as_ref());
    let mut samples = Vec::new();
    input.stream(|block| samples.extend_from_slice(block))?;
    if samples.is_empty() {
        return Err(Error::EmptyStream(format!("input {}", input.name())));
    }
    let fitted = fit(&samples)?;
    let label = args.label.clone().unwrap_or_else(|| match &args.file {
        Some(p) if p.as_os_str() != "-" => p
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "fitted".into()),
        _ => "fitted".into(),
    });
    let out = report(&fitted, &label)?;
    if let Some(path) = &args.qq {
        if fitted.qq_threshold().is_none() {
            return Err(Error::param(
                "qq",
                path.display(),
                "no tail threshold to plot above: the threshold rule needs at least 20 positive \
                 samples that are not point masses",
            ));
        }
        let points = fitted.tail_qq(&samples);
        let title = format!("Tail QQ plot: {label}");
        let note = qq_note(&fitted, points.len());
        write_tail_qq(path, &points, &title, &note)?;
    }
    if fitted.is_black() {
        eprintln!("warning: {BLACK}");
    }
    let mut stdout = io::stdout().lock();
    writeln!(stdout, "{out}").map_err(|e| Error::io("stdout", &e))?;
    Ok(ExitCode::SUCCESS)
}

/// The lines under the QQ plot's title: what lies above the threshold and how it was fitted.
fn qq_note(f: &Fit, points: usize) -> Vec<String> {
    let Some(t) = f.tail else {
        return Vec::new();
    };
    let h = t.choice.hill;
    let searched = format!(
        "{points} samples above the threshold u = {}; Hill {:.3} ± {:.3} on k = {}",
        short(h.threshold),
        h.shape,
        h.se,
        h.k
    );
    let fitted = match t.fitted {
        Some(tf) => format!(
            "fitted: truncated Pareto, shape {:.3}, upper {}; {} outlier(s) as point masses",
            tf.shape,
            short(tf.upper),
            tf.outliers
        ),
        None => "tail not kept (BIC): the lognormal body covers it".into(),
    };
    vec![searched, fitted]
}

/// Four significant digits.
fn short(x: f64) -> String {
    format!(
        "{}",
        fireflies::error::Num(format!("{x:.4e}").parse().unwrap_or(x))
    )
}

/// The JSON object `fireflies fit` prints (keys in this order; see the README).
fn report(f: &Fit, label: &str) -> Result<Value> {
    let n = f.n as f64;
    let mean = f.mean();
    let zeros = f
        .components
        .iter()
        .find(|c| c.role == Role::Zero)
        .map_or(0.0, |c| c.count);
    let components: Vec<Value> = f
        .components
        .iter()
        .map(|c| component(c, n))
        .collect::<Result<_>>()?;
    let tail = f.tail.map(|t| {
        let h = t.choice.hill;
        let mut o = Map::new();
        o.insert("threshold".into(), json!(h.threshold));
        o.insert("k".into(), json!(h.k));
        o.insert("hill".into(), json!(h.shape));
        o.insert("hill_se".into(), json!(h.se));
        o.insert("ks".into(), json!(t.choice.ks));
        o.insert("candidates".into(), json!(t.choice.candidates));
        o.insert("loglik_gain".into(), json!(t.loglik_gain));
        o.insert("loglik_needed".into(), json!(t.loglik_needed));
        o.insert("kept".into(), json!(t.fitted.is_some()));
        if let Some(tf) = t.fitted {
            o.insert("outliers".into(), json!(tf.outliers));
            o.insert(
                "mean_rule".into(),
                serde_json::to_value(tf.rule).unwrap_or_default(),
            );
        }
        Value::Object(o)
    });
    let spec = f.spec();
    let spec_json = serde_json::to_value(&spec)
        .map_err(|e| Error::param("spec", e.to_string(), "cannot be written as JSON"))?;
    let toml_text = toml_entry(label, &spec_json);
    let mut o = Map::new();
    o.insert("n".into(), json!(f.n));
    o.insert("stream_mean".into(), json!(f.stream_mean));
    o.insert("mean".into(), json!(mean));
    let rel = if mean == f.stream_mean {
        0.0
    } else {
        (mean - f.stream_mean) / f.stream_mean
    };
    o.insert("mean_rel_error".into(), json!(rel));
    o.insert("zero_fraction".into(), json!(zeros / n));
    o.insert("components".into(), Value::Array(components));
    o.insert("tail".into(), tail.unwrap_or(Value::Null));
    o.insert("ks_log".into(), json!(f.ks_log));
    o.insert("spec".into(), spec_json);
    o.insert("toml".into(), json!(toml_text));
    if f.is_black() {
        o.insert("warning".into(), json!(BLACK));
    }
    Ok(Value::Object(o))
}

/// What the output says about a stream of only zeros.
const BLACK: &str = "every sample is 0: the fit is the point mass at 0 (mean 0); the harness \
    measures estimators relative to the true mean, so its relative metrics are undefined (NaN) \
    on this generator";

/// The spec as an experiment file's `[[distributions]]` entry, in the inline style of
/// `experiments/*.toml` (a mixture's components one per line).
fn toml_entry(label: &str, spec: &Value) -> String {
    let dist = match spec {
        Value::Object(o) if o.get("kind") == Some(&json!("mixture")) => {
            let items: Vec<String> = o
                .get("components")
                .and_then(Value::as_array)
                .map(|cs| cs.iter().map(|c| format!("    {},\n", inline(c))).collect())
                .unwrap_or_default();
            format!(
                "{{ kind = \"mixture\", components = [\n{}] }}",
                items.concat()
            )
        }
        other => inline(other),
    };
    format!(
        "[[distributions]]\nlabel = {}\ndist = {dist}\n",
        toml::Value::String(label.to_string())
    )
}

/// A JSON value of a spec (objects with bare keys, strings, numbers, arrays) as a TOML inline
/// value. Spec numbers are f64s, which JSON writes with a `.` or an exponent, as TOML floats.
fn inline(v: &Value) -> String {
    match v {
        Value::Object(o) => {
            let fields: Vec<String> = o
                .iter()
                .map(|(k, v)| format!("{k} = {}", inline(v)))
                .collect();
            format!("{{ {} }}", fields.join(", "))
        }
        Value::Array(a) => {
            let items: Vec<String> = a.iter().map(inline).collect();
            format!("[{}]", items.join(", "))
        }
        other => other.to_string(),
    }
}

/// One component: role, weight, count, then the law's `kind` and parameters as an experiment
/// file spells them, then what the fit adds (an atom's sample mean and range, a body part's
/// unconstrained `mu_mle`, `sigma_mle` and sample mean, the tail's sample mean and Hill shape).
fn component(c: &Component, n: f64) -> Result<Value> {
    let mut o = Map::new();
    o.insert(
        "role".into(),
        serde_json::to_value(c.role).unwrap_or_default(),
    );
    o.insert("weight".into(), json!(c.count / n));
    // Whole counts print as integers; body parts share samples by responsibility.
    if c.count.fract() == 0.0 {
        o.insert("count".into(), json!(c.count as u64));
    } else {
        o.insert("count".into(), json!(c.count));
    }
    let law = serde_json::to_value(&c.law)
        .map_err(|e| Error::param("spec", e.to_string(), "cannot be written as JSON"))?;
    if let Value::Object(fields) = law {
        o.extend(fields);
    }
    match c.detail {
        Detail::Atom(a) => {
            o.insert("sample_mean".into(), json!(a.mean));
            o.insert("low".into(), json!(a.low));
            o.insert("high".into(), json!(a.high));
        }
        Detail::Body(b) => {
            o.insert("mu_mle".into(), json!(b.mu_mle));
            o.insert("sigma_mle".into(), json!(b.sigma_mle));
            o.insert("sample_mean".into(), json!(b.sample_mean));
        }
        Detail::Tail(t) => {
            o.insert("sample_mean".into(), json!(t.mean));
            o.insert("hill".into(), json!(t.hill.shape));
        }
        Detail::None => {}
    }
    Ok(Value::Object(o))
}
