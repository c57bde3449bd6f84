//! `kodama-dag serve DIR`: the folder on localhost, files inside it only.

mod common;
use common::*;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};

fn get(addr: &str, target: &str) -> (u16, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    write!(s, "GET {target} HTTP/1.1\r\nHost: {addr}\r\n\r\n").unwrap();
    let mut resp = Vec::new();
    s.read_to_end(&mut resp).unwrap();
    let head_end = resp.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let status: u16 = String::from_utf8_lossy(&resp[9..12]).parse().unwrap();
    (status, resp[head_end + 4..].to_vec())
}

/// `kodama-dag serve DIR` on a free port: the child and the address it printed.
fn serve(dir: &std::path::Path) -> (std::process::Child, String) {
    let mut child = Command::new(BIN)
        .args(["serve", dir.to_str().unwrap(), "--port", "0"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stderr.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|r| r.split('/').next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_owned();
    (child, addr)
}

#[test]
fn serve_gives_the_report_and_nothing_outside_its_folder() {
    let env = Env::new();
    let dir = env.path("report");
    std::fs::create_dir_all(dir.join("plots")).unwrap();
    std::fs::write(dir.join("report.html"), "<!doctype html>hi").unwrap();
    std::fs::write(dir.join("plots/scatter.png"), [137, 80, 78, 71]).unwrap();
    std::fs::write(env.path("secret.txt"), "no").unwrap();
    let (mut child, addr) = serve(&dir);
    let checks = std::panic::catch_unwind(|| {
        assert_eq!(get(&addr, "/"), (200, b"<!doctype html>hi".to_vec()));
        assert_eq!(get(&addr, "/plots/scatter.png").0, 200);
        assert_eq!(get(&addr, "/../secret.txt").0, 404);
        assert_eq!(get(&addr, "/%2e%2e/secret.txt").0, 404);
        assert_eq!(get(&addr, "/missing.png").0, 404);
    });
    child.kill().ok();
    child.wait().ok();
    checks.unwrap();
}

/// Clients that connect and never send, or never read, cost a slot for a bounded time: after
/// 20 idle connections (past the 16 served at once) a real request is still answered, and a
/// client that does not read a 16 MB file is let go while another is served.
#[test]
fn idle_and_stalled_clients_do_not_stall_serve() {
    let env = Env::new();
    let dir = env.path("report");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("report.html"), "<!doctype html>hi").unwrap();
    std::fs::write(dir.join("big.bin"), vec![7u8; 16 << 20]).unwrap();
    let (mut child, addr) = serve(&dir);
    let checks = std::panic::catch_unwind(|| {
        // Never read their 16 MB (streamed: the server holds no copy of it per client).
        let stalled: Vec<TcpStream> = (0..16)
            .map(|_| {
                let mut s = TcpStream::connect(&addr).unwrap();
                write!(s, "GET /big.bin HTTP/1.1\r\n\r\n").unwrap();
                s
            })
            .collect();
        let idle: Vec<TcpStream> = (0..4).map(|_| TcpStream::connect(&addr).unwrap()).collect();
        let t0 = std::time::Instant::now();
        assert_eq!(get(&addr, "/"), (200, b"<!doctype html>hi".to_vec()));
        assert!(t0.elapsed() < std::time::Duration::from_secs(90));
        drop(idle);
        drop(stalled);
    });
    child.kill().ok();
    child.wait().ok();
    checks.unwrap();
}
