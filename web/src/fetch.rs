//! HTTP byte ranges of the package, with the browser's `fetch`: the only way the viewer reads.
//! A server that ignores `Range` (status 200 and the whole file) still works, once: the viewer
//! then holds the whole package and says so.

use std::ops::Range;

use wasm_bindgen::JsCast;
use wasm_bindgen_futures::JsFuture;

use crate::error::Error;

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
}

fn js(url: &str, what: &str, e: wasm_bindgen::JsValue) -> Error {
    Error::Fetch { url: url.to_owned(), problem: format!("{what}: {e:?}") }
}

/// `GET url` with `Range: bytes=start-(end-1)`; `exact`: the answer must hold all of it (the
/// head's request may get less, from a file shorter than it).
pub(crate) async fn range(url: &str, r: Range<u64>, exact: bool) -> Result<Fetched, Error> {
    let init = web_sys::RequestInit::new();
    init.set_method("GET");
    let headers = web_sys::Headers::new().map_err(|e| js(url, "headers", e))?;
    headers
        .set("Range", &format!("bytes={}-{}", r.start, r.end.saturating_sub(1)))
        .map_err(|e| js(url, "Range header", e))?;
    init.set_headers(&headers);
    let request = web_sys::Request::new_with_str_and_init(url, &init).map_err(|e| js(url, "request", e))?;
    let window =
        web_sys::window().ok_or_else(|| Error::Fetch { url: url.into(), problem: "no window".into() })?;
    let response: web_sys::Response = JsFuture::from(window.fetch_with_request(&request))
        .await
        .map_err(|e| js(url, "network", e))?
        .dyn_into()
        .map_err(|e| js(url, "response", e))?;
    let status = response.status();
    if status != 206 && status != 200 {
        return Err(Error::Fetch {
            url: url.into(),
            problem: format!("HTTP {status} {}", response.status_text()),
        });
    }
    let file_len = response
        .headers()
        .get("Content-Range")
        .ok()
        .flatten()
        .and_then(|v| v.rsplit('/').next().and_then(|n| n.trim().parse::<u64>().ok()));
    let buffer = JsFuture::from(response.array_buffer().map_err(|e| js(url, "body", e))?)
        .await
        .map_err(|e| js(url, "body", e))?;
    let bytes = js_sys::Uint8Array::new(&buffer).to_vec();
    let whole_file = status == 200;
    let offset = if whole_file { 0 } else { r.start };
    if !whole_file
        && (bytes.len() as u64 > r.end - r.start || (exact && bytes.len() as u64 != r.end - r.start))
    {
        return Err(Error::Fetch {
            url: url.into(),
            problem: format!(
                "asked for bytes {}..{} ({} bytes), got {} bytes",
                r.start,
                r.end,
                r.end - r.start,
                bytes.len()
            ),
        });
    }
    Ok(Fetched {
        offset,
        file_len: if whole_file { Some(bytes.len() as u64) } else { file_len },
        bytes,
        whole_file,
    })
}
