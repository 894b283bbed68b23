//! A static file server on 127.0.0.1 that answers HTTP range requests, as a static host serving
//! a published site does (docs/web.md), and logs every request: what the browser test serves
//! the site with and counts the bytes of. It names each file's version (ETag) and honours
//! If-Range, as static hosts do, and can be told to misbehave ([`Fault`]: ranges ignored, short
//! bodies, lying Content-Range, error statuses, slowness) for the hostile-server tests. Written by
//! hand (std only): a test needs a few dozen lines, not a web framework; Python's `http.server`
//! has no ranges.

use std::io::{BufRead, BufReader, Read, Seek, SeekFrom, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// One request served.
#[derive(Clone, Debug)]
pub struct Served {
    pub path: String,
    /// The `Range` header as sent.
    pub range: Option<String>,
    pub status: u16,
    /// Body bytes sent.
    pub bytes: u64,
}

/// What the server gets wrong, for requests of `path` after the first `after` of them (counted
/// since the server started), `times` times (None: from then on): the hostile servers a published page must survive.
#[derive(Clone, Debug)]
pub struct Fault {
    pub path: String,
    pub after: usize,
    pub times: Option<usize>,
    pub kind: FaultKind,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultKind {
    /// 200 and the whole file to a range request (a server or CDN edge without ranges).
    IgnoreRanges,
    /// 206 with the range's Content-Range but half its body (a dropped connection).
    ShortBody,
    /// 206 whose Content-Range names bytes 64 further on than those sent.
    WrongContentRange,
    /// This status, no body.
    Status(u16),
    /// The right answer, this many milliseconds late.
    DelayMs(u64),
}

/// The server; it stops with the test process.
#[derive(Debug)]
pub struct Server {
    pub port: u16,
    pub log: Arc<Mutex<Vec<Served>>>,
    /// Set at any time: applies to the requests that come after.
    pub fault: Arc<Mutex<Option<Fault>>>,
}

fn content_type(path: &Path) -> &'static str {
    match path.extension().and_then(|e| e.to_str()) {
        Some("html") => "text/html; charset=utf-8",
        Some("js") => "text/javascript",
        Some("wasm") => "application/wasm",
        Some("json") => "application/json",
        Some("jpg" | "jpeg") => "image/jpeg",
        _ => "application/octet-stream",
    }
}

/// Serves `root` on a free port.
pub fn serve(root: &Path) -> std::io::Result<Server> {
    let listener = TcpListener::bind("127.0.0.1:0")?;
    let port = listener.local_addr()?.port();
    let log = Arc::new(Mutex::new(Vec::new()));
    let fault: Arc<Mutex<Option<Fault>>> = Arc::new(Mutex::new(None));
    let (root, sink, faults) = (root.to_path_buf(), log.clone(), fault.clone());
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let (root, sink, faults) = (root.clone(), sink.clone(), faults.clone());
            std::thread::spawn(move || {
                let _ = handle(stream, &root, &sink, &faults);
            });
        }
    });
    Ok(Server { port, log, fault })
}

/// The request's path and its Range and If-Range headers.
fn read_request(stream: &TcpStream) -> std::io::Result<(String, Option<String>, Option<String>)> {
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut line = String::new();
    reader.read_line(&mut line)?;
    let target = line.split_whitespace().nth(1).unwrap_or("/").to_owned();
    let (mut range, mut if_range) = (None, None);
    loop {
        let mut h = String::new();
        if reader.read_line(&mut h)? == 0 || h.trim().is_empty() {
            break;
        }
        if let Some((k, v)) = h.split_once(':') {
            if k.trim().eq_ignore_ascii_case("range") {
                range = Some(v.trim().to_owned());
            } else if k.trim().eq_ignore_ascii_case("if-range") {
                if_range = Some(v.trim().to_owned());
            }
        }
    }
    let path = target.split('?').next().unwrap_or("/").trim_start_matches('/');
    Ok((if path.is_empty() { "index.html" } else { path }.to_owned(), range, if_range))
}

/// The fault for this request, if any (`served`: earlier requests of the same path).
fn fault_for(faults: &Mutex<Option<Fault>>, path: &str, served: usize) -> Option<FaultKind> {
    let f = faults.lock().ok()?.clone()?;
    (f.path == path && served >= f.after && f.times.is_none_or(|n| served < f.after + n)).then_some(f.kind)
}

fn handle(
    mut stream: TcpStream,
    root: &Path,
    log: &Mutex<Vec<Served>>,
    faults: &Mutex<Option<Fault>>,
) -> std::io::Result<()> {
    let (path, range, if_range) = read_request(&stream)?;
    let served = log.lock().map(|l| l.iter().filter(|s| s.path == path).count()).unwrap_or(0);
    let fault = fault_for(faults, &path, served);
    if let Some(FaultKind::DelayMs(ms)) = fault {
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
    let file: Option<PathBuf> =
        (!path.split('/').any(|c| c == ".." || c.is_empty())).then(|| root.join(&path));
    let mut entry = Served { path: path.clone(), range: range.clone(), status: 404, bytes: 0 };
    let result = match (file.filter(|f| f.is_file()), fault) {
        (_, Some(FaultKind::Status(code))) => {
            entry.status = code;
            stream.write_all(
                format!("HTTP/1.1 {code} Fault\r\nContent-Length: 0\r\nConnection: close\r\n\r\n").as_bytes(),
            )
        }
        (None, _) => {
            stream.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
        }
        (Some(f), fault) => answer(&mut stream, &f, range.as_deref(), if_range.as_deref(), fault, &mut entry),
    };
    if let Ok(mut l) = log.lock() {
        l.push(entry);
    }
    result
}

/// A file's answer: the range asked for (206), or the whole file where there is no range, the
/// range is unsatisfiable (416) or If-Range names another version of it; with its ETag (size and
/// modification time), and `fault` applied.
fn answer(
    stream: &mut TcpStream,
    f: &Path,
    range: Option<&str>,
    if_range: Option<&str>,
    fault: Option<FaultKind>,
    entry: &mut Served,
) -> std::io::Result<()> {
    let mut file = std::fs::File::open(f)?;
    let meta = file.metadata()?;
    let size = meta.len();
    let modified = meta.modified()?.duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    let etag = format!("\"{size}-{modified}\"");
    let same_version = if_range.is_none_or(|v| v == etag);
    let range = range.filter(|_| same_version && fault != Some(FaultKind::IgnoreRanges));
    let wanted = range.and_then(|r| {
        let (a, b) = r.strip_prefix("bytes=")?.split_once('-')?;
        let a: u64 = a.parse().ok()?;
        let b: u64 = if b.is_empty() { size.saturating_sub(1) } else { b.parse().ok()? };
        (a < size && a <= b).then(|| (a, b.min(size - 1)))
    });
    let (status, start, mut len, extra) = match (range.is_some(), wanted) {
        (_, Some((a, b))) => {
            let shown = if fault == Some(FaultKind::WrongContentRange) { a + 64 } else { a };
            (206, a, b - a + 1, format!("Content-Range: bytes {shown}-{}/{size}\r\n", shown + b - a))
        }
        (true, None) => (416, 0, 0, format!("Content-Range: bytes */{size}\r\n")),
        (false, None) => (200, 0, size, String::new()),
    };
    if fault == Some(FaultKind::ShortBody) && status == 206 {
        len /= 2;
    }
    let reason = match status {
        206 => "Partial Content",
        416 => "Range Not Satisfiable",
        _ => "OK",
    };
    let head = format!(
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {}\r\nContent-Length: {len}\r\nAccept-Ranges: bytes\r\n\
         ETag: {etag}\r\n{extra}Cache-Control: no-store\r\nConnection: close\r\n\r\n",
        content_type(f)
    );
    stream.write_all(head.as_bytes())?;
    file.seek(SeekFrom::Start(start))?;
    let sent = std::io::copy(&mut (&mut file).take(len), stream)?;
    entry.status = status;
    entry.bytes = sent;
    Ok(())
}
