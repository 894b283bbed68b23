//! A static file server on 127.0.0.1 that answers HTTP range requests, as a static host serving
//! a published site does (docs/web.md), and logs every request: what the browser test serves
//! the site with and counts the bytes of. Written by hand (std only): a test needs a few dozen
//! lines, not a web framework; Python's `http.server` has no ranges.

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

/// The server; it stops with the test process.
#[derive(Debug)]
pub struct Server {
    pub port: u16,
    pub log: Arc<Mutex<Vec<Served>>>,
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
    let (root, sink) = (root.to_path_buf(), log.clone());
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let (root, sink) = (root.clone(), sink.clone());
            std::thread::spawn(move || {
                let _ = handle(stream, &root, &sink);
            });
        }
    });
    Ok(Server { port, log })
}

fn handle(mut stream: TcpStream, root: &Path, log: &Mutex<Vec<Served>>) -> std::io::Result<()> {
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut line = String::new();
    reader.read_line(&mut line)?;
    let target = line.split_whitespace().nth(1).unwrap_or("/").to_owned();
    let mut range = None;
    loop {
        let mut h = String::new();
        if reader.read_line(&mut h)? == 0 || h.trim().is_empty() {
            break;
        }
        if let Some((k, v)) = h.split_once(':')
            && k.trim().eq_ignore_ascii_case("range")
        {
            range = Some(v.trim().to_owned());
        }
    }
    let path = target.split('?').next().unwrap_or("/").trim_start_matches('/');
    let path = if path.is_empty() { "index.html" } else { path };
    let file: Option<PathBuf> =
        (!path.split('/').any(|c| c == ".." || c.is_empty())).then(|| root.join(path));
    let mut entry = Served { path: path.to_owned(), range: range.clone(), status: 404, bytes: 0 };
    let result = match file.filter(|f| f.is_file()) {
        None => stream.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"),
        Some(f) => {
            let mut file = std::fs::File::open(&f)?;
            let size = file.metadata()?.len();
            let wanted = range.as_deref().and_then(|r| {
                let (a, b) = r.strip_prefix("bytes=")?.split_once('-')?;
                let a: u64 = a.parse().ok()?;
                let b: u64 = if b.is_empty() { size.saturating_sub(1) } else { b.parse().ok()? };
                (a < size && a <= b).then(|| (a, b.min(size - 1)))
            });
            let (status, start, len, extra) = match (range.is_some(), wanted) {
                (_, Some((a, b))) => (206, a, b - a + 1, format!("Content-Range: bytes {a}-{b}/{size}\r\n")),
                (true, None) => (416, 0, 0, format!("Content-Range: bytes */{size}\r\n")),
                (false, None) => (200, 0, size, String::new()),
            };
            let reason = match status {
                206 => "Partial Content",
                416 => "Range Not Satisfiable",
                _ => "OK",
            };
            let head = format!(
                "HTTP/1.1 {status} {reason}\r\nContent-Type: {}\r\nContent-Length: {len}\r\nAccept-Ranges: bytes\r\n\
                 {extra}Cache-Control: no-store\r\nConnection: close\r\n\r\n",
                content_type(&f)
            );
            stream.write_all(head.as_bytes())?;
            file.seek(SeekFrom::Start(start))?;
            let sent = std::io::copy(&mut (&mut file).take(len), &mut stream)?;
            entry.status = status;
            entry.bytes = sent;
            Ok(())
        }
    };
    if let Ok(mut l) = log.lock() {
        l.push(entry);
    }
    result
}
