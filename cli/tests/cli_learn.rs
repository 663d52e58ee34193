//! The learnt agent through the `activesense` binary, as a user runs it: a short training
//! run writes a policy, its log and its curve; `eval` and `episode` play that policy; a
//! corrupt or mismatched policy file is a one-line error naming the file.

mod common;
use common::{activesense, s, scratch};

#[test]
fn train_then_play_the_policy() {
    let dir = scratch("cli-train");
    let out = dir.join("run");
    let o = activesense(&[
        "train",
        "--rot-bins",
        "1",
        "--updates",
        "12",
        "--imitation-updates",
        "8",
        "--envs",
        "4",
        "--segment",
        "8",
        "--log-every",
        "4",
        "--no-progress",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("learning_rate"),
        "hyper-parameters printed: {stderr}"
    );
    for f in ["policy.policy", "log.csv", "log.json", "curve.svg"] {
        assert!(out.join(f).exists(), "{f} written");
    }
    let csv = std::fs::read_to_string(out.join("log.csv")).unwrap();
    assert_eq!(
        csv.lines().count(),
        1 + 3,
        "header + one row per 4 updates: {csv}"
    );
    let policy = out.join("policy.policy");
    let eval = dir.join("eval");
    let o = activesense(&[
        "eval",
        "--agents",
        "learnt,heuristic-1",
        "--rot-bins",
        "1",
        "--plans",
        "3",
        "--policy",
        s(&policy),
        "--no-progress",
        "--out",
        s(&eval),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(eval.join("results.json")).unwrap()).unwrap();
    let rows = json["results"].as_array().unwrap();
    assert_eq!(rows[0]["agent"], "learnt");
    assert!(rows[0]["cost"].as_f64().is_some());
    assert_eq!(json["options"]["policy_files"].as_array().unwrap().len(), 1);
    let o = activesense(&[
        "episode",
        "--seed",
        "1000001",
        "--agent",
        "learnt",
        "--policy",
        s(&policy),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("agent learnt"));
    // The K = 1 policy cannot play the K = 10 setting.
    let o = activesense(&[
        "episode",
        "--seed",
        "1000001",
        "--agent",
        "learnt",
        "--rot-bins",
        "10",
        "--policy",
        s(&policy),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("K = 10"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_corrupt_policy_is_a_clear_error() {
    let dir = scratch("cli-corrupt");
    let bad = dir.join("broken.policy");
    std::fs::write(&bad, b"ASPOLICY but not really").unwrap();
    let o = activesense(&[
        "eval",
        "--agents",
        "learnt",
        "--rot-bins",
        "1",
        "--plans",
        "1",
        "--policy",
        s(&bad),
        "--out",
        s(&dir.join("e")),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("broken.policy"), "{err}");
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    // On a device `learnt` is the int8 policy it carries: episodes verified against the
    // in-process run.
    let o = activesense(&[
        "sim",
        "--link",
        "loopback",
        "--agent",
        "learnt",
        "--rot-bins",
        "10",
        "--episodes",
        "2",
        "--verify",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("verified bit-identical"));
    // Uploading a file that is not a policy: one line naming it, nothing sent.
    let o = activesense(&["policy", "upload", "--link", "loopback", "--int8", s(&bad)]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("broken.policy"));
    std::fs::remove_dir_all(&dir).ok();
}
