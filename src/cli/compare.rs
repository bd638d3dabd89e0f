//! `fireflies compare`: the image metrics of one EXR against a reference EXR
//! (`fireflies::image::metrics`), as text or as one JSON object.

use clap::Args;
use fireflies::Result;
use fireflies::image::Image;
use fireflies::image::metrics::{FireflyRule, Metrics};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The image to judge (OpenEXR, linear RGB).
    image: PathBuf,
    /// The reference image, of the same size (e.g. from `fireflies reference`).
    #[arg(long)]
    reference: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// A firefly pixel's luminance exceeds this factor times the reference's ...
    #[arg(long, default_value_t = FireflyRule::DEFAULT_FACTOR)]
    firefly_factor: f64,
    /// ... plus this floor.
    #[arg(long, default_value_t = FireflyRule::DEFAULT_FLOOR)]
    firefly_floor: f64,
}

pub fn run(args: &CompareArgs) -> Result<ExitCode> {
    let rule = FireflyRule::new(args.firefly_factor, args.firefly_floor)?;
    let image = Image::read_exr(&args.image)?;
    let reference = Image::read_exr(&args.reference)?;
    let m = Metrics::compute(&image, &reference, rule)?;
    if args.json {
        let mut row = serde_json::Map::new();
        row.insert("image".into(), args.image.display().to_string().into());
        row.insert(
            "reference".into(),
            args.reference.display().to_string().into(),
        );
        if let serde_json::Value::Object(fields) = serde_json::to_value(&m).unwrap_or_default() {
            row.extend(fields);
        }
        println!("{}", serde_json::Value::Object(row));
    } else {
        let bias = match m.mean_bias_relative {
            Some(r) => format!(
                "{:+.4e} ({:+.3}% of {:.4e})",
                m.mean_bias,
                100.0 * r,
                m.reference_mean_luminance
            ),
            None => format!("{:+.4e} (reference mean luminance 0)", m.mean_bias),
        };
        println!("image      {}", args.image.display());
        println!(
            "reference  {} ({}x{})",
            args.reference.display(),
            m.width,
            m.height
        );
        println!("rmse       {:.6e}", m.rmse);
        println!("relmse     {:.6e}", m.relmse);
        println!("psnr_db    {:.4}", m.psnr_db);
        println!("ssim       {:.6}", m.ssim);
        println!("mean_bias  {bias}");
        println!(
            "fireflies  {} pixels ({:.4}%): luminance > {} x reference + {}",
            m.firefly_pixels,
            100.0 * m.firefly_fraction,
            m.firefly_factor,
            m.firefly_floor
        );
    }
    Ok(ExitCode::SUCCESS)
}
