//! Lighting files (`--lights FILE` of `grotto render`, `view` and `publish`): a package's lights
//! changed without a rebuild (grotto_format::lighting), IES files read beside the lighting file.

use std::path::Path;

use grotto_format::lighting::{self, LightingError};

use crate::error::{Error, Result};
use crate::scene::lighting::Relight;

/// IES files larger than this are not photometric data (the largest tables are ~1 MB).
const MAX_IES_BYTES: u64 = 16 << 20;

/// Reads the lighting file at `path` and merges it with `package`'s lights.
pub fn relight_of(package: &grotto_format::Scene, path: &Path) -> Result<Relight> {
    let at = |e: LightingError| Error::Lighting {
        path: match &e.file {
            Some(f) => path.parent().unwrap_or(Path::new("")).join(f).display().to_string(),
            None => path.display().to_string(),
        },
        line: e.line,
        problem: e.problem,
    };
    let whole = |problem: String| Error::Lighting { path: path.display().to_string(), line: None, problem };
    let text = std::fs::read_to_string(path).map_err(|e| whole(e.to_string()))?;
    let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let read_ies = |name: &str| read_ies(&dir.join(name));
    let file = lighting::parse(&text, read_ies).map_err(at)?;
    crate::scene::lighting::merged((&package.lights, &package.circuits), &file).map_err(whole)
}

/// The text of the IES file at `file`, refused where it is larger than any photometric table.
pub fn read_ies(file: &Path) -> std::result::Result<String, String> {
    let len = std::fs::metadata(file).map_err(|e| e.to_string())?.len();
    if len > MAX_IES_BYTES {
        return Err(format!("{len} bytes: more than an IES file holds ({MAX_IES_BYTES} at most)"));
    }
    // IES files are ASCII, sometimes Latin-1 in their keywords.
    std::fs::read(file).map(|b| String::from_utf8_lossy(&b).into_owned()).map_err(|e| e.to_string())
}

/// The lighting a job uses with `switches` (`--circuits NAME=on|off`) applied: the lighting
/// file's (`relight`), else the package's own circuits. None where there is nothing to change.
pub fn with_circuits(
    package: &grotto_format::Scene,
    relight: Option<Relight>,
    switches: &[(String, bool)],
) -> Result<Option<Relight>> {
    if switches.is_empty() {
        return Ok(relight);
    }
    let problem = |p: String| Error::Setting { name: "circuits", problem: p };
    let mut r = match relight {
        Some(r) => r,
        None if !package.circuits.is_empty() => Relight::of_package(&package.lights, &package.circuits),
        None => {
            return Err(problem(
                "the package has no circuits (a lighting file, --lights, gives some)".into(),
            ));
        }
    };
    for (name, on) in switches {
        let known = r.circuits.iter().map(|c| c.name.as_str()).collect::<Vec<_>>().join(", ");
        let c = r
            .circuits
            .iter_mut()
            .find(|c| &c.name == name)
            .ok_or_else(|| problem(format!("no circuit named {name:?} (there are: {known})")))?;
        c.on = *on;
    }
    Ok(Some(r))
}

/// `NAME=on` or `NAME=off` (`--circuits`).
pub fn parse_switch(s: &str) -> std::result::Result<(String, bool), String> {
    match s.rsplit_once('=') {
        Some((name, "on")) if !name.is_empty() => Ok((name.to_string(), true)),
        Some((name, "off")) if !name.is_empty() => Ok((name.to_string(), false)),
        _ => Err(format!("{s:?}: expected NAME=on or NAME=off")),
    }
}
