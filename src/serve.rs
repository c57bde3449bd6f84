//! `kodama-dag serve DIR`: a folder on localhost, for browsers that refuse `file://` pages (the
//! report's 3D view works from disk in Chromium and Firefox, but some setups block it).
//!
//! GET and HEAD only, files under DIR only (no `..`, no symlinks out of it), one thread per
//! connection up to a small cap, bound to 127.0.0.1: a viewer, not a web server.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Component, Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

/// Connections served at once; more wait in the listen queue.
const MAX_CONNECTIONS: usize = 16;
/// How long one connection may take in all, request to last byte: a client that reads a byte
/// a minute (or not at all) gives its slot back.
const CONNECTION_DEADLINE: Duration = Duration::from_secs(120);
/// How long one write may wait on a client that does not read.
const WRITE_TIMEOUT: Duration = Duration::from_secs(20);
/// The longest request head read.
const MAX_HEAD: u64 = 16 * 1024;

/// Serves `dir` on 127.0.0.1:`port` (0: any free port) until killed; prints the address first.
pub fn serve(dir: &Path, port: u16) -> Result<(), String> {
    let root = dir
        .canonicalize()
        .map_err(|e| format!("{}: {e}", dir.display()))?;
    if !root.is_dir() {
        return Err(format!("{}: not a folder", dir.display()));
    }
    let listener =
        TcpListener::bind(("127.0.0.1", port)).map_err(|e| format!("127.0.0.1:{port}: {e}"))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    let page = if root.join("report.html").is_file() {
        "report.html"
    } else {
        ""
    };
    eprintln!(
        "serving {} at http://{addr}/{page} (Ctrl-C to stop)",
        root.display()
    );
    let root = Arc::new(root);
    let busy = Arc::new(AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        while busy.load(Ordering::Acquire) >= MAX_CONNECTIONS {
            std::thread::sleep(Duration::from_millis(5));
        }
        busy.fetch_add(1, Ordering::AcqRel);
        let (root, busy) = (Arc::clone(&root), Arc::clone(&busy));
        std::thread::spawn(move || {
            let _ = handle(stream, &root);
            busy.fetch_sub(1, Ordering::AcqRel);
        });
    }
    Ok(())
}

fn handle(mut stream: TcpStream, root: &Path) -> std::io::Result<()> {
    let start = std::time::Instant::now();
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    let mut line = String::new();
    let mut head = BufReader::new((&stream).take(MAX_HEAD));
    head.read_line(&mut line)?;
    // The rest of the head: headers are not needed.
    let mut skip = String::new();
    while head.read_line(&mut skip)? > 2 {
        skip.clear();
    }
    let mut parts = line.split_whitespace();
    let (method, target) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    if method != "GET" && method != "HEAD" {
        return respond(&mut stream, 405, "text/plain", b"GET or HEAD only\n", true);
    }
    let Some(path) = resolve(root, target) else {
        return respond(&mut stream, 404, "text/plain", b"not found\n", true);
    };
    let Ok(mut file) = kodama_nodes::io::open::open_regular(&path) else {
        return respond(&mut stream, 404, "text/plain", b"not found\n", true);
    };
    let len = file.metadata()?.len();
    write!(
        stream,
        "HTTP/1.1 200 OK\r\nContent-Type: {}\r\nContent-Length: {len}\r\nConnection: close\r\n\r\n",
        content_type(&path)
    )?;
    if method == "GET" {
        // Streamed, not read whole: a report's 3D tiles can be large, and many clients many.
        let mut buf = vec![0u8; 64 * 1024];
        loop {
            let n = file.read(&mut buf)?;
            if n == 0 {
                break;
            }
            write_before(&mut stream, &buf[..n], start + CONNECTION_DEADLINE)?;
        }
    }
    stream.flush()
}

/// `data` written to `stream`, every write waiting no longer than the time left before
/// `deadline`: a client reading a byte now and then cannot hold its slot past the deadline.
fn write_before(
    stream: &mut TcpStream,
    mut data: &[u8],
    deadline: std::time::Instant,
) -> std::io::Result<()> {
    while !data.is_empty() {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                "the client took too long",
            ));
        }
        stream.set_write_timeout(Some(left.min(WRITE_TIMEOUT)))?;
        let n = stream.write(data)?;
        if n == 0 {
            return Err(std::io::ErrorKind::WriteZero.into());
        }
        data = &data[n..];
    }
    Ok(())
}

/// The file under `root` a request target names (`/` is `report.html`), or `None` when it
/// would leave `root` or is not a file.
fn resolve(root: &Path, target: &str) -> Option<PathBuf> {
    let path = target.split(['?', '#']).next().unwrap_or("");
    let decoded = percent_decode(path)?;
    let rel = decoded.trim_start_matches('/');
    let rel = if rel.is_empty() { "report.html" } else { rel };
    let rel = Path::new(rel);
    if !rel.components().all(|c| matches!(c, Component::Normal(_))) {
        return None;
    }
    let full = root.join(rel).canonicalize().ok()?;
    (full.starts_with(root) && full.is_file()).then_some(full)
}

fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    let s = String::from_utf8(out).ok()?;
    (!s.contains('\0')).then_some(s)
}

fn content_type(p: &Path) -> &'static str {
    match p.extension().and_then(|e| e.to_str()).unwrap_or("") {
        "html" => "text/html; charset=utf-8",
        "js" | "mjs" => "text/javascript",
        "json" => "application/json",
        "png" => "image/png",
        "svg" => "image/svg+xml",
        "csv" => "text/csv; charset=utf-8",
        "md" | "txt" => "text/plain; charset=utf-8",
        "glb" => "model/gltf-binary",
        "tif" | "tiff" => "image/tiff",
        _ => "application/octet-stream",
    }
}

fn respond(
    s: &mut TcpStream,
    code: u16,
    ty: &str,
    body: &[u8],
    with_body: bool,
) -> std::io::Result<()> {
    let reason = match code {
        200 => "OK",
        404 => "Not Found",
        _ => "Method Not Allowed",
    };
    write!(
        s,
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {ty}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    if with_body {
        s.write_all(body)?;
    }
    s.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_stay_inside_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        std::fs::write(root.join("report.html"), "x").unwrap();
        std::fs::create_dir(root.join("plots")).unwrap();
        std::fs::write(root.join("plots/a b.png"), "x").unwrap();
        assert_eq!(resolve(&root, "/"), Some(root.join("report.html")));
        assert_eq!(
            resolve(&root, "/plots/a%20b.png?x=1"),
            Some(root.join("plots/a b.png"))
        );
        for bad in [
            "/../etc/passwd",
            "/plots/../../x",
            "/%2e%2e/x",
            "//etc/passwd",
            "/plots",
            "/%zz",
            "/a%00b",
        ] {
            assert_eq!(resolve(&root, bad), None, "{bad}");
        }
    }
}
