//! The small things a user trips on , each through the real binary: a
//! closed stdout, an unwritable `--out`, `plan --json` read back by `--plan`, the
//! `--termination` values in `--help`, a negative `--stop-risk`, and link errors in words.

mod common;

use common::{activesense, s, scratch};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

fn text(out: &std::process::Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `activesense episode … | head -1`: the reader goes away after one line; the command
/// stops quietly with status 0 (it panicked with status 101).
#[test]
fn closed_stdout_ends_quietly() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_activesense"))
        .args(["episode", "--seed", "1000000"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    // The read end is closed here (dropped with the reader); the episode prints ~40 lines.
    assert!(first.starts_with("episode: "), "{first}");
    let out = child.wait_with_output().unwrap();
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// `eval --out` where nothing can be written fails before the run starts.
#[test]
fn eval_refuses_an_unwritable_out_before_running() {
    let dir = scratch("unwritable-out");
    let file = dir.join("a-file");
    std::fs::write(&file, "not a directory").unwrap();
    let out_dir = file.join("results");
    let out = activesense(&[
        "eval",
        "--plans",
        "1000",
        "--no-progress",
        "--out",
        s(&out_dir),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(!out.status.success(), "{stdout}{stderr}");
    assert!(
        stderr.contains("cannot create the output directory"),
        "{stderr}"
    );
    assert!(!stderr.contains("evaluating"), "the run started: {stderr}");
}

/// The file `plan --json` writes is a plan file `episode --plan` accepts: the same room.
#[test]
fn plan_json_is_a_plan_file() {
    let dir = scratch("plan-json");
    let json = dir.join("plan.json");
    let out = activesense(&["plan", "--seed", "1000003", "--json", s(&json)]);
    assert!(out.status.success(), "{:?}", text(&out));
    let (stdout, _) = text(&out);
    let vertices: usize = stdout
        .split(", ")
        .find_map(|w| w.strip_suffix(" vertices"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(doc["vertices"].as_array().map(Vec::len), Some(vertices));
    let out = activesense(&["episode", "--plan", s(&json), "--rot-bins", "1"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
}

/// `--help` lists the termination rules; an unknown one is told the choices.
#[test]
fn termination_values_are_in_help() {
    for cmd in [
        &["episode", "--help"][..],
        &["eval", "--help"],
        &["sim", "--help"],
    ] {
        let (stdout, _) = text(&activesense(cmd));
        for v in ["oracle", "confident", "action-limit"] {
            assert!(stdout.contains(&format!("- {v}:")), "{cmd:?}: {stdout}");
        }
    }
    let out = activesense(&["episode", "--seed", "1", "--termination", "soon"]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(
        stderr.contains("[possible values: oracle, confident, action-limit]"),
        "{stderr}"
    );
}

/// `--stop-risk -1` is a value out of range, not an unknown flag.
#[test]
fn negative_stop_risk_is_a_range_error() {
    for (flag, want) in [
        ("--stop-risk", "is not a stop risk"),
        ("--min-observability", "is not an observability threshold"),
    ] {
        let out = activesense(&["episode", "--seed", "1", flag, "-1"]);
        let (_, stderr) = text(&out);
        assert!(!out.status.success());
        assert!(stderr.contains(want), "{stderr}");
        assert!(!stderr.contains("unexpected argument"), "{stderr}");
    }
}

/// Link errors are sentences, not Rust debug structs.
#[test]
fn link_errors_are_plain_words() {
    // Nothing listens on a port just freed.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let link = format!("tcp:127.0.0.1:{port}");
    for cmd in [
        vec!["sim", "--link", link.as_str(), "--episodes", "1"],
        vec!["policy", "info", "--link", link.as_str()],
    ] {
        let out = activesense(&cmd);
        let (_, stderr) = text(&out);
        assert!(!out.status.success());
        assert!(
            stderr.contains(&format!(
                "error: opening {link}: cannot connect to 127.0.0.1:{port}"
            )),
            "{stderr}"
        );
        assert!(
            !stderr.contains("Tcp(") && !stderr.contains("{ "),
            "{stderr}"
        );
    }
}
