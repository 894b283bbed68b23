//! A scan given where a package is expected (`grotto render scan.laz`, `grotto view scan.e57`): it
//! is packed once by `grotto-pack build`, the same build a user would run, into grotto's cache, and
//! the package is opened from there (again on the next run while the scan is unchanged). The
//! runtime does not link the preprocessor: it stays slim, and its browser build must not carry
//! it; it runs the `grotto-pack` installed beside `grotto` (or `$GROTTO_PACK`, or the PATH's).

use crate::{Error, Result};
use std::io::Read;
use std::path::{Path, PathBuf};

/// Which scan format a file's first bytes name (LAS/LAZ, PLY, E57), if any.
pub fn scan_kind(path: &Path) -> Result<Option<&'static str>> {
    let mut magic = [0u8; 8];
    let mut f = std::fs::File::open(path).map_err(|e| scan_error(path, format!("cannot read it: {e}")))?;
    let n = f.read(&mut magic).map_err(|e| scan_error(path, format!("cannot read it: {e}")))?;
    Ok(grotto_format::scan_format(&magic[..n]))
}

fn scan_error(path: &Path, problem: String) -> Error {
    Error::Scan { path: path.display().to_string(), problem }
}

/// Where grotto keeps the packages it packed from scans: `$GROTTO_CACHE_DIR`, else
/// `$XDG_CACHE_HOME/grotto`, else `~/.cache/grotto`, else the system's temporary folder.
pub fn cache_dir() -> PathBuf {
    let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    var("GROTTO_CACHE_DIR")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("grotto")))
        .or_else(|| var("HOME").map(|d| d.join(".cache").join("grotto")))
        .unwrap_or_else(|| std::env::temp_dir().join("grotto"))
}

/// The package to open for `path`: `path` itself unless it is a scan; a scan's package in
/// [`cache_dir`] (`KEY/NAME.grotto`), packed now by `grotto-pack build` unless the same scan (path, size, modification
/// time) was packed by this version before. `say` gets a line for the user about what happened.
pub fn package_for(path: &Path, mut say: impl FnMut(&str)) -> Result<PathBuf> {
    let Some(kind) = scan_kind(path)? else {
        return Ok(path.to_path_buf());
    };
    let meta = std::fs::metadata(path).map_err(|e| scan_error(path, format!("cannot read it: {e}")))?;
    let canonical = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
    let modified = meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
    // FNV-1a: a name that changes with the scan, not a checksum of its bytes (a survey's scans
    // run to gigabytes; their size and modification time change when they are rewritten).
    let mut key = 0xcbf2_9ce4_8422_2325u64;
    let parts = [
        canonical.to_string_lossy().as_bytes().to_vec(),
        meta.len().to_le_bytes().to_vec(),
        modified.map_or(0, |d| d.as_nanos()).to_le_bytes().to_vec(),
        env!("CARGO_PKG_VERSION").as_bytes().to_vec(),
    ];
    for b in parts.iter().flatten() {
        key = (key ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    let stem = path.file_stem().map_or_else(|| "scan".into(), |s| s.to_string_lossy().into_owned());
    // A folder per scan, so the package keeps the scan's name (`grotto publish` serves it by it).
    let dir = cache_dir().join(format!("{key:016x}"));
    let out = dir.join(format!("{stem}.grotto"));
    if out.is_file() {
        say(&format!(
            "{}: a {kind} scan; opening the package packed from it before, {}",
            path.display(),
            out.display()
        ));
        return Ok(out);
    }
    std::fs::create_dir_all(&dir).map_err(|e| {
        scan_error(
            path,
            format!("cannot create grotto's cache folder {} to pack it into: {e}", dir.display()),
        )
    })?;
    let pack = std::env::var_os("GROTTO_PACK").map(PathBuf::from).unwrap_or_else(|| {
        let beside = std::env::current_exe().ok().and_then(|exe| {
            exe.parent().map(|d| d.join(format!("grotto-pack{}", std::env::consts::EXE_SUFFIX)))
        });
        beside.filter(|p| p.is_file()).unwrap_or_else(|| PathBuf::from("grotto-pack"))
    });
    say(&format!(
        "{}: a {kind} scan; packing it with `{} build` into {} (once: later runs open that package)",
        path.display(),
        pack.display(),
        out.display()
    ));
    let t0 = std::time::Instant::now();
    // grotto-pack's report goes to stderr, so that `grotto render --json` keeps stdout to itself.
    let status = std::process::Command::new(&pack)
        .arg("build")
        .arg(path)
        .arg("-o")
        .arg(&out)
        // Its work folder (tile bins, kept for resuming) would double what the cache holds.
        .arg("--clean")
        .stdout(std::process::Stdio::from(std::io::stderr()))
        .status()
        .map_err(|e| {
            scan_error(
                path,
                format!(
                    "it is a {kind} scan, and grotto-pack, which packs scans, did not run ({}: {e}); install it beside grotto (cargo build --release -p grotto-preprocess) or set GROTTO_PACK, or pack it yourself: `grotto-pack build FILE -o FILE.grotto`",
                    pack.display()
                ),
            )
        })?;
    if !status.success() || !out.is_file() {
        return Err(scan_error(
            path,
            format!(
                "it is a {kind} scan, and `grotto-pack build` could not pack it ({status}; its message is above)"
            ),
        ));
    }
    say(&format!("packed in {:.1} s", t0.elapsed().as_secs_f64()));
    Ok(out)
}
