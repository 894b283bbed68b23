//! HTTP byte ranges of the package, with the browser's `fetch`: the only way the viewer reads.
//! A server that ignores `Range` (status 200 and the whole file) still works, once: the viewer
//! then holds the whole package and says so.
//!
//! What a server may get wrong is checked, not trusted: the status, `Content-Range` against the
//! range asked for and the file's size, the body's length. Every request after the first carries
//! `If-Range` with the first answer's validator (ETag, else Last-Modified), so a package replaced
//! on the server mid-visit comes back whole (status 200) instead of as a range of another file,
//! and is reported as replaced. Each request has a deadline, so a server that stops answering
//! cannot hang a step forever.

use std::ops::Range;

use wasm_bindgen::JsCast;
use wasm_bindgen_futures::JsFuture;

use grotto_format::Package;

use crate::error::Error;

/// The package as fetched so far, and what was fetched.
pub(crate) struct Source {
    pub(crate) url: String,
    pub(crate) package_bytes: u64,
    pub(crate) fetched_bytes: u64,
    pub(crate) requests: u32,
    pub(crate) no_ranges: bool,
    /// What the first answer said of the file: later ones must agree (fetch.rs).
    pub(crate) expect: Expect,
}

/// Merge ranges closer than this: fewer requests for a few wasted bytes.
pub(crate) const FETCH_GAP: u64 = 64 << 10;

impl Source {
    /// Head, then directory: a package with no section yet.
    pub(crate) async fn open(url: &str) -> Result<(Self, Package), Error> {
        let mut src = Self {
            url: url.to_owned(),
            package_bytes: 0,
            fetched_bytes: 0,
            requests: 0,
            no_ranges: false,
            expect: Expect::default(),
        };
        let head = range(url, 0..Package::HEAD_BYTES, false, None).await?;
        src.count(&head);
        let name = url.rsplit('/').next().unwrap_or(url).to_owned();
        if head.whole_file {
            src.no_ranges = true;
            src.package_bytes = head.bytes.len() as u64;
            return Ok((src, Package::from_bytes(name, &head.bytes)?));
        }
        let file_len = head.file_len.ok_or_else(|| Error::Fetch {
            url: url.into(),
            problem: "the server answered a range request without Content-Range (the file's size)".into(),
            transient: false,
        })?;
        src.expect = Expect { file_len: Some(file_len), validator: head.validator.clone() };
        src.package_bytes = file_len;
        let dir = Package::directory_range(name.clone(), &head.bytes, file_len)?;
        let d = range(url, dir.clone(), true, Some(&src.expect)).await?;
        src.count(&d);
        if d.whole_file {
            // The server gave up ranges after the head: the whole file is here.
            src.no_ranges = true;
            return Ok((src, Package::from_bytes(name, &d.bytes)?));
        }
        Ok((src, Package::from_directory(name, file_len, &head.bytes, dir.start, &d.bytes)?))
    }

    fn count(&mut self, f: &Fetched) {
        self.fetched_bytes += f.bytes.len() as u64;
        self.requests += 1;
    }
}

/// Fetches `ranges` one after another (they are merged already, so few).
pub(crate) async fn fetch_all(
    url: String,
    ranges: Vec<Range<u64>>,
    expect: Expect,
) -> Result<Vec<Fetched>, Error> {
    let mut out = Vec::with_capacity(ranges.len());
    for r in ranges {
        out.push(range(&url, r, true, Some(&expect)).await?);
    }
    Ok(out)
}

/// Inserts fetched ranges into the package, counting them.
pub(crate) fn insert(pkg: &mut Package, src: &mut Source, fetched: &[Fetched]) -> Result<(), Error> {
    for f in fetched {
        src.count(f);
        // A whole file (a server that ignored the range, fetch.rs) fills the package at once.
        src.no_ranges |= f.whole_file;
        pkg.insert(f.offset, &f.bytes)?;
    }
    Ok(())
}

/// What one request gave.
#[derive(Debug)]
pub(crate) struct Fetched {
    /// Where `bytes` start in the file.
    pub offset: u64,
    pub bytes: Vec<u8>,
    /// The file's size, where the server said (`Content-Range: bytes a-b/SIZE`).
    pub file_len: Option<u64>,
    /// The server sent the whole file instead of the range (no range support).
    pub whole_file: bool,
    /// The file's version as the server names it (ETag, else Last-Modified).
    pub validator: Option<String>,
}

/// What the requests after the first check their answers against.
#[derive(Clone, Debug, Default)]
pub(crate) struct Expect {
    pub file_len: Option<u64>,
    pub validator: Option<String>,
}

fn js(url: &str, what: &str, e: wasm_bindgen::JsValue, transient: bool) -> Error {
    Error::Fetch { url: url.to_owned(), problem: format!("{what}: {e:?}"), transient }
}

fn wrong(url: &str, problem: String) -> Error {
    Error::Fetch { url: url.to_owned(), problem, transient: false }
}

/// A request's deadline: 30 s, plus a second for every 100 kB (a connection slower than 100 kB/s
/// is not one a cave can be streamed over anyway).
fn deadline_ms(r: &Range<u64>) -> u32 {
    (30_000 + (r.end - r.start) / 100).min(600_000) as u32
}

/// `GET url` with `Range: bytes=start-(end-1)`; `exact`: the answer must hold all of it (the
/// head's request may get less, from a file shorter than it). `expect`: what the first answer
/// said of the file (None for the first request).
pub(crate) async fn range(
    url: &str,
    r: Range<u64>,
    exact: bool,
    expect: Option<&Expect>,
) -> Result<Fetched, Error> {
    let init = web_sys::RequestInit::new();
    init.set_method("GET");
    let headers = web_sys::Headers::new().map_err(|e| js(url, "headers", e, false))?;
    headers
        .set("Range", &format!("bytes={}-{}", r.start, r.end.saturating_sub(1)))
        .map_err(|e| js(url, "Range header", e, false))?;
    if let Some(v) = expect.and_then(|e| e.validator.as_deref()) {
        headers.set("If-Range", v).map_err(|e| js(url, "If-Range header", e, false))?;
    }
    init.set_headers(&headers);
    init.set_signal(Some(&web_sys::AbortSignal::timeout_with_u32(deadline_ms(&r))));
    let request =
        web_sys::Request::new_with_str_and_init(url, &init).map_err(|e| js(url, "request", e, false))?;
    let window = web_sys::window().ok_or_else(|| wrong(url, "no window".into()))?;
    let response: web_sys::Response = JsFuture::from(window.fetch_with_request(&request))
        .await
        .map_err(|e| js(url, "network (or no answer in time)", e, true))?
        .dyn_into()
        .map_err(|e| js(url, "response", e, false))?;
    let status = response.status();
    if status != 206 && status != 200 {
        // 5xx and 408/429 may pass; a missing or forbidden file will not come back by asking.
        let transient = status >= 500 || status == 408 || status == 429;
        return Err(Error::Fetch {
            url: url.into(),
            problem: format!("HTTP {status} {}", response.status_text()),
            transient,
        });
    }
    let header = |name: &str| response.headers().get(name).ok().flatten();
    let validator = header("ETag").or_else(|| header("Last-Modified"));
    let content_range = header("Content-Range");
    let buffer = JsFuture::from(response.array_buffer().map_err(|e| js(url, "body", e, true))?)
        .await
        .map_err(|e| js(url, "body (or no answer in time)", e, true))?;
    let bytes = js_sys::Uint8Array::new(&buffer).to_vec();
    let whole_file = status == 200;
    if let Some(expect) = expect {
        let replaced = |how: String| Error::Replaced { url: url.into(), problem: how };
        if let (Some(was), Some(now)) = (expect.validator.as_deref(), validator.as_deref())
            && was != now
        {
            return Err(replaced(format!("its version went from {was} to {now}")));
        }
        // A whole file to a range request with If-Range: the server ignored the range (the same
        // version, which the viewer can use whole) or the file changed (and the server did not
        // say so by a validator, or said nothing at all).
        if whole_file
            && (expect.validator.is_some() && validator.is_none()
                || expect.file_len != Some(bytes.len() as u64))
        {
            return Err(replaced(format!(
                "asked for a range of it, got a whole file of {} bytes",
                bytes.len()
            )));
        }
    }
    let file_len = if whole_file {
        Some(bytes.len() as u64)
    } else {
        let (start, end, total) = parse_content_range(content_range.as_deref())
            .ok_or_else(|| wrong(url, format!("206 with a Content-Range of {content_range:?}")))?;
        if start != r.start || end >= total || end >= r.end {
            return Err(wrong(
                url,
                format!(
                    "asked for bytes {}..{}, the server's Content-Range says {start}..{} of {total}",
                    r.start,
                    r.end,
                    end + 1
                ),
            ));
        }
        if end + 1 - start != bytes.len() as u64 {
            // Content-Range and the body disagree: a connection cut short.
            return Err(Error::Fetch {
                url: url.into(),
                problem: format!("bytes {start}..{} announced, {} arrived", end + 1, bytes.len()),
                transient: true,
            });
        }
        Some(total)
    };
    if let (Some(expect), Some(now)) = (expect.and_then(|e| e.file_len), file_len)
        && expect != now
    {
        return Err(Error::Replaced {
            url: url.into(),
            problem: format!("it was {expect} bytes, the server now says {now}"),
        });
    }
    let offset = if whole_file { 0 } else { r.start };
    if !whole_file && exact && bytes.len() as u64 != r.end - r.start {
        return Err(Error::Fetch {
            url: url.into(),
            problem: format!(
                "asked for bytes {}..{} ({} bytes), got {} bytes",
                r.start,
                r.end,
                r.end - r.start,
                bytes.len()
            ),
            transient: true,
        });
    }
    Ok(Fetched { offset, file_len, bytes, whole_file, validator })
}

/// `bytes START-END/TOTAL` (inclusive END).
fn parse_content_range(v: Option<&str>) -> Option<(u64, u64, u64)> {
    let (span, total) = v?.trim().strip_prefix("bytes ")?.split_once('/')?;
    let (a, b) = span.split_once('-')?;
    let (a, b, total) = (a.trim().parse().ok()?, b.trim().parse().ok()?, total.trim().parse().ok()?);
    (a <= b).then_some((a, b, total))
}
