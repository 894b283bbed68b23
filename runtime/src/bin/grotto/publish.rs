//! `grotto publish`: a static web site that shows a package in the browser.

use std::path::PathBuf;
use std::process::ExitCode;

#[derive(clap::Args, Debug)]
pub(crate) struct PublishArgs {
    pub(crate) package: PathBuf,
    /// The site's folder (made; replaced whole if it exists).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// The viewer bundle (default: $GROTTO_WEB_BUNDLE, else `web` beside the binary's folder,
    /// where scripts/build-web.sh puts it: target/web).
    #[arg(long)]
    pub(crate) bundle: Option<PathBuf>,
    /// The page's title (default: the package's name).
    #[arg(long)]
    pub(crate) title: Option<String>,
    /// The camera the page opens on (default: the package's first).
    #[arg(long)]
    pub(crate) camera: Option<String>,
    /// Quality preset the page starts with: fast, balanced, high (as grotto render --quality).
    #[arg(long)]
    pub(crate) quality: Option<String>,
    /// Most light bounces.
    #[arg(long)]
    pub(crate) bounces: Option<u32>,
    /// Fixed exposure (default: automatic, as grotto render).
    #[arg(long)]
    pub(crate) exposure: Option<f32>,
    /// Points of interest and tours to add to the package's (TOML: [[poi]], [[tour]] as in a
    /// manifest, docs/manifest.md); one named as one of the package's replaces it.
    #[arg(long)]
    pub(crate) story: Option<PathBuf>,
    /// A lighting file changing the package's lights ([[light]], [[circuit]]; docs/lighting.md):
    /// the page and its picture are lit by it.
    #[arg(long)]
    pub(crate) lights: Option<PathBuf>,
    /// Size WIDTHxHEIGHT of the still picture a browser without WebGPU shows (rendered here,
    /// at the first tour stop or the page's camera).
    #[arg(long, default_value = "800x600", value_parser = grotto_runtime::cli::render_job::parse_size)]
    pub(crate) picture: (u32, u32),
    /// Publish without the still picture (no GPU here to render it).
    #[arg(long)]
    pub(crate) no_picture: bool,
    /// Render the picture on the software rasteriser.
    #[arg(long)]
    pub(crate) software: bool,
    /// Machine-readable output.
    #[arg(long)]
    pub(crate) json: bool,
}

pub(crate) fn publish(a: PublishArgs) -> anyhow::Result<ExitCode> {
    use grotto_runtime::cli::publish;
    if let Some(q) = &a.quality {
        anyhow::ensure!(
            grotto_runtime::settings::Quality::parse(q).is_some(),
            "--quality {q}: expected fast, balanced or high"
        );
    }
    let mut viewer_options = serde_json::Map::new();
    if let Some(c) = a.camera {
        viewer_options.insert("camera".into(), c.into());
    }
    if let Some(q) = a.quality {
        viewer_options.insert("quality".into(), q.into());
    }
    if let Some(b) = a.bounces {
        viewer_options.insert("bounces".into(), b.into());
    }
    if let Some(e) = a.exposure {
        anyhow::ensure!(e.is_finite() && e > 0.0, "--exposure {e}: expected a number > 0");
        viewer_options.insert("exposure".into(), e.into());
    }
    let summary = publish::publish(&publish::PublishOptions {
        package: grotto_runtime::cli::scan_input::package_for(&a.package, |m| eprintln!("{m}"))?,
        out: a.out,
        bundle: a.bundle,
        title: a.title,
        viewer_options,
        story: a.story,
        lights: a.lights,
        picture: (!a.no_picture).then(|| publish::Picture {
            width: a.picture.0,
            height: a.picture.1,
            gpu: grotto_runtime::gpu::GpuOptions { prefer_software: a.software, ..Default::default() },
        }),
    })?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        let mb = |b: u64| b as f64 / 1e6;
        println!(
            "wrote {}: {} ({:.2} MB package, {:.2} MB viewer of which {:.2} MB wasm; {} points of \
             interest, {} tours); serve it from any static host that answers range requests (docs/web.md)",
            summary.site,
            summary.files.join(", "),
            mb(summary.package_bytes),
            mb(summary.bundle_bytes),
            mb(summary.wasm_bytes),
            summary.pois,
            summary.tours
        );
    }
    Ok(ExitCode::SUCCESS)
}
