//! The inspection page as a person uses it, in a real browser: `activesense episode --agent
//! learnt --json` records a trajectory, `activesense inspect` makes the page, headless
//! Chromium opens it, and the test drives the page's own controls through the DevTools
//! protocol (mouse clicks on the time slider and the overlay checkbox, arrow keys, the
//! channel slider), takes screenshots, and checks that the heat map changes between steps
//! and with the overlay, and that the page raised no JavaScript error.
//!
//! Chromium comes from the distribution (`cargo xtask setup` installs it). Without it the
//! test is skipped with a message, unless `ACTIVESENSE_REQUIRE_BROWSER=1` (set by `cargo
//! xtask ci`), where a missing browser fails. `ACTIVESENSE_INSPECT_PNG=FILE` also writes the
//! full-page screenshot to FILE (how `docs/inspect.png` is made).

mod common;
use common::{activesense, s, scratch};

use serde_json::{json, Value};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::{Message, WebSocket};

/// Records a learnt-agent episode and makes its page; returns the page path.
fn make_page(dir: &Path, name: &str, seed: &str, rot_bins: &str) -> PathBuf {
    let json = dir.join(format!("{name}.json"));
    let html = dir.join(format!("{name}.html"));
    let o = activesense(&[
        "episode",
        "--seed",
        seed,
        "--agent",
        "learnt",
        "--rot-bins",
        rot_bins,
        "--quiet",
        "--json",
        s(&json),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = activesense(&["inspect", s(&json), "--out", s(&html)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let page = std::fs::read_to_string(&html).unwrap();
    // Self-contained: nothing fetched from anywhere.
    for bad in ["http://", "https://", "<script src", "<link"] {
        assert!(!page.contains(bad), "page references {bad}");
    }
    html
}

fn find_chromium() -> Option<PathBuf> {
    if let Ok(p) = std::env::var("CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    for dir in std::env::split_paths(&path) {
        for name in ["chromium", "chromium-browser", "google-chrome", "chrome"] {
            let p = dir.join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    None
}

/// A headless Chromium and a DevTools-protocol session on its page.
struct Browser {
    child: Child,
    ws: WebSocket<TcpStream>,
    next_id: u64,
    events: Vec<Value>,
    _profile: PathBuf,
}

impl Browser {
    fn launch(exe: &Path, profile: PathBuf) -> Browser {
        let mut child = Command::new(exe)
            .args([
                "--headless=new",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--no-default-browser-check",
                "--hide-scrollbars",
                "--remote-debugging-port=0",
                "--window-size=1600,860",
                &format!("--user-data-dir={}", s(&profile)),
                "about:blank",
            ])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start chromium");
        // Everything that can fail before the Browser (whose Drop ends Chromium) exists is
        // done in `connect`; on failure the child is killed here, then the test fails.
        match connect(&profile) {
            Ok(ws) => Browser {
                child,
                ws,
                next_id: 0,
                events: Vec::new(),
                _profile: profile,
            },
            Err(e) => {
                let _ = child.kill();
                let _ = child.wait();
                panic!("{e}");
            }
        }
    }

    fn read(&mut self) -> Value {
        loop {
            match self.ws.read().expect("devtools message") {
                Message::Text(t) => return serde_json::from_str(&t).unwrap(),
                Message::Close(_) => panic!("devtools closed"),
                _ => {}
            }
        }
    }

    /// Sends one command and returns its result; events that arrive meanwhile are kept.
    fn call(&mut self, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let msg = json!({ "id": id, "method": method, "params": params });
        self.ws.send(Message::Text(msg.to_string())).unwrap();
        loop {
            let v = self.read();
            if v["id"] == id {
                assert!(v.get("error").is_none(), "{method}: {v}");
                return v["result"].clone();
            }
            self.events.push(v);
        }
    }

    fn wait_event(&mut self, method: &str) {
        if self.events.iter().any(|e| e["method"] == method) {
            return;
        }
        loop {
            let v = self.read();
            let hit = v["method"] == method;
            self.events.push(v);
            if hit {
                return;
            }
        }
    }

    /// Evaluates `expr` in the page and returns its value.
    fn eval(&mut self, expr: &str) -> Value {
        let r = self.call(
            "Runtime.evaluate",
            json!({ "expression": expr, "returnByValue": true, "awaitPromise": true }),
        );
        assert!(r.get("exceptionDetails").is_none(), "{expr}: {r}");
        r["result"]["value"].clone()
    }

    fn open(&mut self, page: &Path) {
        self.events.clear();
        self.call(
            "Page.navigate",
            json!({ "url": format!("file://{}", s(page)) }),
        );
        self.wait_event("Page.loadEventFired");
    }

    /// Centre of element `id` in CSS pixels.
    fn centre(&mut self, id: &str) -> (f64, f64, f64, f64) {
        let r = self.eval(&format!(
            "(() => {{ const r = document.getElementById('{id}').getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; }})()"
        ));
        let f = |i: usize| r[i].as_f64().unwrap();
        (f(0), f(1), f(2), f(3))
    }

    fn click(&mut self, x: f64, y: f64) {
        for kind in ["mousePressed", "mouseReleased"] {
            self.call(
                "Input.dispatchMouseEvent",
                json!({ "type": kind, "x": x, "y": y, "button": "left", "clickCount": 1 }),
            );
        }
    }

    fn key(&mut self, key: &str, code: u32) {
        for kind in ["keyDown", "keyUp"] {
            self.call(
                "Input.dispatchKeyEvent",
                json!({ "type": kind, "key": key, "code": key, "windowsVirtualKeyCode": code }),
            );
        }
    }

    /// PNG of element `id` (or the whole page), base64 as the protocol sends it.
    fn screenshot(&mut self, id: Option<&str>) -> String {
        let mut params = json!({ "format": "png" });
        if let Some(id) = id {
            let (x, y, w, h) = self.centre(id);
            params["clip"] = json!({ "x": x, "y": y, "width": w, "height": h, "scale": 1 });
        }
        self.call("Page.captureScreenshot", params)["data"]
            .as_str()
            .unwrap()
            .to_string()
    }

    fn attr(&mut self, name: &str) -> String {
        self.eval(&format!("document.body.getAttribute('{name}')"))
            .as_str()
            .unwrap_or_default()
            .to_string()
    }

    /// Every JavaScript error the page reported so far.
    fn js_errors(&mut self) -> Vec<String> {
        // Drain what has arrived by asking for something harmless.
        self.eval("1");
        self.events
            .iter()
            .filter(|e| {
                e["method"] == "Runtime.exceptionThrown"
                    || (e["method"] == "Runtime.consoleAPICalled" && e["params"]["type"] == "error")
                    || (e["method"] == "Log.entryAdded" && e["params"]["entry"]["level"] == "error")
            })
            .map(|e| e.to_string())
            .collect()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.ws.send(Message::Text(
            json!({ "id": 0, "method": "Browser.close" }).to_string(),
        ));
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(5) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Waits for Chromium's DevTools port (it writes the one it chose into DevToolsActivePort),
/// finds the page target and opens a WebSocket to it.
fn connect(profile: &Path) -> Result<WebSocket<TcpStream>, String> {
    let port_file = profile.join("DevToolsActivePort");
    let t0 = Instant::now();
    let port: u16 = loop {
        if let Ok(text) = std::fs::read_to_string(&port_file) {
            if let Some(p) = text.lines().next().and_then(|l| l.trim().parse().ok()) {
                break p;
            }
        }
        if t0.elapsed() > Duration::from_secs(60) {
            return Err("chromium did not open its DevTools port".into());
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let ws_url = loop {
        let list = http_get(port, "/json/list");
        let pages: Vec<Value> = serde_json::from_str(&list).unwrap_or_default();
        if let Some(u) = pages
            .iter()
            .find(|p| p["type"] == "page")
            .and_then(|p| p["webSocketDebuggerUrl"].as_str())
        {
            break u.to_string();
        }
        if t0.elapsed() > Duration::from_secs(60) {
            return Err(format!("no page target on DevTools port {port}"));
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let stream = TcpStream::connect(("127.0.0.1", port)).map_err(|e| e.to_string())?;
    stream
        .set_read_timeout(Some(Duration::from_secs(60)))
        .map_err(|e| e.to_string())?;
    let (ws, _) = tungstenite::client(ws_url.as_str(), stream)
        .map_err(|e| format!("websocket handshake: {e}"))?;
    Ok(ws)
}

/// `GET path` on Chromium's DevTools HTTP endpoint (HTTP/1.1: it keeps the connection
/// open, so the body is read by its Content-Length).
fn http_get(port: u16, path: &str) -> String {
    let Ok(mut c) = TcpStream::connect(("127.0.0.1", port)) else {
        return String::new();
    };
    let _ = c.set_read_timeout(Some(Duration::from_secs(10)));
    let _ = write!(
        c,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n\r\n"
    );
    let mut buf = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        let text = String::from_utf8_lossy(&buf).into_owned();
        if let Some((head, body)) = text.split_once("\r\n\r\n") {
            let len = head
                .lines()
                .find_map(|l| {
                    let (k, v) = l.split_once(':')?;
                    k.eq_ignore_ascii_case("content-length")
                        .then(|| v.trim().parse::<usize>().ok())?
                })
                .unwrap_or(0);
            if body.len() >= len {
                return body[..len].to_string();
            }
        }
        match c.read(&mut chunk) {
            Ok(0) | Err(_) => return String::new(),
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
        }
    }
}

fn base64_decode(s: &str) -> Vec<u8> {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let (mut out, mut acc, mut bits) = (Vec::new(), 0u32, 0);
    for c in s.bytes().filter(|c| *c != b'=') {
        let v = A.iter().position(|a| *a == c).expect("base64 digit") as u32;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    out
}

#[test]
fn page_steps_through_an_episode_in_headless_chromium() {
    let Some(exe) = find_chromium() else {
        let msg = "chromium not found (install it: apt-get install chromium, or `cargo xtask setup`; or set CHROMIUM=/path)";
        if std::env::var("ACTIVESENSE_REQUIRE_BROWSER").as_deref() == Ok("1") {
            panic!("{msg}");
        }
        eprintln!("\n*** SKIPPED page_steps_through_an_episode_in_headless_chromium: {msg} ***\n");
        return;
    };
    let dir = scratch("inspect-browser");
    let page = make_page(&dir, "k1", "1000005", "1");
    let mut b = Browser::launch(&exe, dir.join("profile"));
    for domain in ["Runtime.enable", "Page.enable", "Log.enable"] {
        b.call(domain, json!({}));
    }
    b.open(&page);
    assert_eq!(b.attr("data-step"), "0");
    assert_eq!(b.attr("data-gbp"), "off");
    let n: u64 = b
        .eval("Number(document.getElementById('step').max)")
        .as_u64()
        .unwrap();
    assert!(n >= 5, "episode too short for the test: {n} steps");
    let heat0 = b.screenshot(Some("heat"));

    // A person clicks at 60 % of the time slider: the slider jumps there.
    let (x, y, w, h) = b.centre("step");
    b.click(x + 0.6 * w, y + h / 2.0);
    let t1: u64 = b.attr("data-step").parse().unwrap();
    assert!(
        t1 > 0 && t1 <= n,
        "clicking the slider moved it to step {t1} of {n}"
    );
    // ... and steps on with the right arrow key (the slider has the focus).
    b.key("ArrowRight", 39);
    let t2: u64 = b.attr("data-step").parse().unwrap();
    assert_eq!(t2, (t1 + 1).min(n), "arrow key steps");
    let label = b.eval("document.getElementById('step-label').textContent");
    assert_eq!(label, json!(format!("step {t2} / {n}")));
    let heat1 = b.screenshot(Some("heat"));
    assert_ne!(
        heat0, heat1,
        "heat map unchanged between step 0 and step {t2}"
    );

    // Toggle the guided-back-propagation overlay with a click on its checkbox.
    let (x, y, w, h) = b.centre("gbp");
    b.click(x + w / 2.0, y + h / 2.0);
    assert_eq!(b.attr("data-gbp"), "on");
    let caption = b.eval("document.getElementById('heat-caption').textContent");
    assert!(
        caption
            .as_str()
            .unwrap()
            .starts_with("guided back-propagation"),
        "{caption}"
    );
    let heat_gbp = b.screenshot(Some("heat"));
    assert!(heat1 != heat_gbp, "overlay changed nothing");
    // The overlay follows the step: back to the first step with the Home key on the page,
    // the arrows step on and back, and the right arrow walks to where we were.
    b.eval("document.activeElement.blur()");
    b.key("Home", 36);
    assert_eq!(b.attr("data-step"), "0");
    let first = b.screenshot(Some("heat"));
    assert!(first != heat_gbp, "overlay did not follow the step");
    b.key("ArrowRight", 39);
    assert_eq!(b.attr("data-step"), "1");
    b.key("ArrowLeft", 37);
    assert_eq!(b.attr("data-step"), "0");
    for _ in 0..t2 {
        b.key("ArrowRight", 39);
    }
    assert_eq!(b.attr("data-step"), t2.to_string());
    assert!(
        b.screenshot(Some("heat")) == heat_gbp,
        "same step, same picture"
    );

    // The last frame shows the final (refined) estimate beside the belief argmax.
    b.eval("document.activeElement.blur()");
    b.key("End", 35);
    assert_eq!(b.attr("data-step"), n.to_string());
    let legend = b.eval("document.getElementById('room-legend').textContent");
    assert!(
        legend
            .as_str()
            .unwrap()
            .contains("final answer (refined, error 0."),
        "{legend}"
    );
    b.key("Home", 36);
    let legend = b.eval("document.getElementById('room-legend').textContent");
    assert!(
        !legend.as_str().unwrap().contains("final answer"),
        "{legend}"
    );

    let page_png = base64_decode(&b.screenshot(None));
    assert_eq!(&page_png[1..4], b"PNG");
    let shot = dir.join("inspect.png");
    std::fs::write(&shot, &page_png).unwrap();
    if let Ok(p) = std::env::var("ACTIVESENSE_INSPECT_PNG") {
        std::fs::write(&p, &page_png).unwrap();
        eprintln!("wrote {p}");
    }
    let errors = b.js_errors();
    assert!(errors.is_empty(), "JavaScript errors: {errors:?}");
    assert_eq!(
        b.eval("document.getElementById('errors').textContent"),
        json!("")
    );

    // K = 10: the rotation-channel slider shows another plane of the belief.
    let page10 = make_page(&dir, "k10", "1000003", "10");
    b.open(&page10);
    assert_eq!(
        b.eval("Number(document.getElementById('channel').max)"),
        json!(9)
    );
    b.eval("document.activeElement.blur()");
    for _ in 0..2 {
        b.key("ArrowRight", 39);
    }
    assert_eq!(b.attr("data-step"), "2");
    // Late in the episode, when the belief is no longer flat.
    let (x, y, w, h) = b.centre("step");
    b.click(x + 0.9 * w, y + h / 2.0);
    let c0 = b.screenshot(Some("heat"));
    let (x, y, w, h) = b.centre("channel");
    b.click(x + 0.55 * w, y + h / 2.0);
    let k: u64 = b.attr("data-channel").parse().unwrap();
    assert!(k > 0, "channel slider did not move");
    assert_ne!(
        c0,
        b.screenshot(Some("heat")),
        "channel {k} looks like channel 0"
    );
    let errors = b.js_errors();
    assert!(errors.is_empty(), "JavaScript errors (K = 10): {errors:?}");
    drop(b);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn inspect_rejects_what_it_cannot_show() {
    let dir = scratch("inspect-errors");
    let bad = dir.join("broken.json");
    std::fs::write(&bad, "{\"format\": 2, \"steps\": [").unwrap();
    let o = activesense(&["inspect", s(&bad), "--out", s(&dir.join("x.html"))]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("broken.json") && err.contains("not valid JSON"),
        "{err}"
    );
    // A baseline's trajectory has no policy to inspect.
    let base = dir.join("heuristic.json");
    let o = activesense(&[
        "episode",
        "--seed",
        "1000000",
        "--quiet",
        "--json",
        s(&base),
    ]);
    assert!(o.status.success());
    let o = activesense(&["inspect", s(&base), "--out", s(&dir.join("x.html"))]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("heuristic.json") && err.contains("no inspection data"),
        "{err}"
    );
    // Another format version.
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(&base).unwrap()).unwrap();
    v["format"] = json!(99);
    let other = dir.join("future.json");
    std::fs::write(&other, v.to_string()).unwrap();
    let o = activesense(&["inspect", s(&other), "--out", s(&dir.join("x.html"))]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("future.json") && err.contains("format 99"),
        "{err}"
    );
    assert!(!dir.join("x.html").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn aggregate_writes_its_pictures_and_numbers() {
    let dir = scratch("inspect-aggregate");
    let out = dir.join("fig4");
    let o = activesense(&[
        "inspect",
        "--aggregate",
        "--agent",
        "learnt",
        "--plans",
        "3",
        "--no-progress",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["aggregate.json", "aggregate.md", "grid.svg", "centred.svg"] {
        assert!(out.join(f).exists(), "{f} written");
    }
    let v: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("aggregate.json")).unwrap())
            .unwrap();
    assert_eq!(v["plans"], json!(3));
    let decisions =
        v["measure"]["decisions"].as_u64().unwrap() + v["rotate"]["decisions"].as_u64().unwrap();
    assert!(decisions >= 6, "{decisions} decisions in 3 episodes");
    assert_eq!(v["measure"]["grid_mean"].as_array().unwrap().len(), 30 * 30);
    // Only the float policy has maps.
    let o = activesense(&[
        "inspect",
        "--aggregate",
        "--agent",
        "heuristic-1",
        "--out",
        s(&out),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--agent learnt"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
