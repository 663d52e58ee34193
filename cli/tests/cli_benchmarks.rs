//! The §4.3 greedy benchmarks, the §4.4 ablations and the eq.-15 curves through the
//! `activesense` binary, as a user runs them.

mod common;
use common::{activesense, s, scratch};

#[test]
fn greedy_agents_evaluate_with_curves_and_decision_times() {
    let out = scratch("bench-greedy");
    let o = activesense(&[
        "eval",
        "--agents",
        "oigm,oigm-cost,eem,heuristic-1",
        "--rot-bins",
        "1,10",
        "--plans",
        "3",
        "--curve-plans",
        "2",
        "--no-progress",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    for agent in ["oigm", "oigm-cost", "eem", "heuristic-1"] {
        assert!(
            md.contains(&format!("| {agent} |")),
            "row for {agent}: {md}"
        );
    }
    assert!(md.contains("time per decision (ms)") && md.contains("Perf(π)"));
    for k in [1, 10] {
        let svg = std::fs::read_to_string(out.join(format!("utility-k{k}.svg"))).unwrap();
        assert!(svg.contains("mean belief entropy") && svg.contains("<polyline"));
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let first = &json["results"][0];
    assert_eq!(first["agent"], "oigm");
    // The entropy curve starts at the uniform belief and never rises above it.
    let h: Vec<f64> = first["curve"]["entropy"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(h.len() > 10 && h.iter().all(|&v| v <= h[0] + 1e-9));
    let timing: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("timing.json")).unwrap()).unwrap();
    assert!(timing["group_decision_ms"][0].as_f64().unwrap() > 0.0);
}

#[test]
fn extra_measurements_follow_episodes_past_the_oracle_stop() {
    let out = scratch("bench-extra");
    let o = activesense(&[
        "eval",
        "--agents",
        "heuristic-1,oigm",
        "--rot-bins",
        "1",
        "--plans",
        "3",
        "--extra-measurements",
        "3",
        "--max-actions",
        "200",
        "--no-progress",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["extra.json", "extra.md", "extra.svg"] {
        assert!(out.join(f).exists(), "{f}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("extra.json")).unwrap()).unwrap();
    let h1 = &json["results"][0];
    assert_eq!(h1["agent"], "heuristic-1");
    // Heuristic-1 measures every 6th action: with 200 actions every stopped episode gets
    // all three extra ranges.
    let n: Vec<u64> = h1["episodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(n.len(), 4);
    assert!(n[0] > 0 && n.iter().all(|&k| k == n[0]), "{n:?}");
}

#[test]
fn greedy_agents_are_refused_on_an_instrument_with_a_reason() {
    let o = activesense(&[
        "sim",
        "--link",
        "loopback",
        "--agent",
        "oigm",
        "--episodes",
        "1",
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("host-side benchmark") && e.contains("eval"),
        "{e}"
    );
}

#[test]
fn ablated_policies_train_and_play_with_their_mask() {
    let dir = scratch("bench-ablation");
    let out = dir.join("no-scans");
    let o = activesense(&[
        "train",
        "--rot-bins",
        "1",
        "--updates",
        "6",
        "--imitation-updates",
        "4",
        "--envs",
        "4",
        "--segment",
        "8",
        "--inputs",
        "no-scans",
        "--registration-reward",
        "0",
        "--no-progress",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let policy = out.join("policy.policy");
    let o = activesense(&[
        "episode",
        "--seed",
        "1000000",
        "--agent",
        "learnt",
        "--policy",
        s(&policy),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A scan-blind network is the EDM-only instrument's: its int8 form says so (blob byte 18).
    let o = activesense(&[
        "policy",
        "quantize",
        "--policy",
        s(&policy),
        "--out",
        s(&dir.join("x.q8")),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("--instrument edm"));
    assert_eq!(std::fs::read(dir.join("x.q8")).unwrap()[18], 1);
    // A network denied its belief map is no instrument's: refused by name.
    let blind = dir.join("no-belief");
    let o = activesense(&[
        "train",
        "--rot-bins",
        "1",
        "--updates",
        "2",
        "--imitation-updates",
        "1",
        "--envs",
        "2",
        "--segment",
        "4",
        "--inputs",
        "no-belief",
        "--no-progress",
        "--out",
        s(&blind),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = activesense(&[
        "policy",
        "quantize",
        "--policy",
        s(&blind.join("policy.policy")),
        "--out",
        s(&dir.join("y.q8")),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("no-belief") && e.contains("policy.policy"),
        "{e}"
    );
    let o = activesense(&[
        "train",
        "--rot-bins",
        "1",
        "--inputs",
        "no-eyes",
        "--out",
        s(&dir),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no-belief"));
}

#[test]
fn observability_threshold_is_validated_and_used() {
    let o = activesense(&[
        "eval",
        "--agents",
        "heuristic-1",
        "--plans",
        "2",
        "--min-observability",
        "nan",
        "--out",
        "/tmp/never",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("observability threshold"));
    // An impossible threshold (above what any readings reach with the heading known)
    // never lets the oracle stop: the episode runs to its action limit.
    let o = activesense(&[
        "episode",
        "--seed",
        "1000000",
        "--min-observability",
        "0.9",
        "--max-actions",
        "40",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("ActionLimit after 40 actions"), "{out}");
}

#[test]
fn stop_risk_is_validated_and_carried() {
    // Refused with a plain message on every command that takes it (before any work).
    let plan = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/plans/l-room.json"
    );
    for bad in ["nan", "0", "1.5", "-0.1", "inf"] {
        for cmd in [
            &["episode", "--seed", "1000000"][..],
            &["eval", "--plans", "1", "--out", "/tmp/never"][..],
            &["sim", "--link", "loopback", "--episodes", "1"][..],
            &["serial", "run", "--port", "/dev/null", "--plan", plan][..],
        ] {
            let flag = format!("--stop-risk={bad}");
            let mut args = cmd.to_vec();
            args.push(&flag);
            let o = activesense(&args);
            assert!(!o.status.success(), "{args:?} accepted");
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(err.contains("is not a stop risk"), "{args:?}: {err}");
        }
    }
    for cmd in ["sim", "serial"] {
        let mut args = vec![cmd];
        if cmd == "serial" {
            args.extend(["run", "--port", "/dev/null", "--plan", plan]);
        }
        args.extend(["--min-observability", "nan"]);
        let o = activesense(&args);
        assert!(!o.status.success(), "{args:?} accepted");
        assert!(String::from_utf8_lossy(&o.stderr).contains("observability threshold"));
    }
    // The episode records it in its spec.
    let dir = scratch("stop-risk");
    let json = dir.join("run.json");
    let o = activesense(&[
        "episode",
        "--seed",
        "1000000",
        "--termination",
        "confident",
        "--stop-risk",
        "0.05",
        "--json",
        s(&json),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(t["spec"]["config"]["stop_risk"].as_f64(), Some(0.05));
    // The device is told both and plays the same episodes as the in-process run.
    let o = activesense(&[
        "sim",
        "--link",
        "loopback",
        "--episodes",
        "2",
        "--termination",
        "confident",
        "--stop-risk",
        "0.05",
        "--min-observability",
        "0.2",
        "--verify",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("every episode verified bit-identical"));
}

/// `activesense calibrate` on a handful of plans: it writes Rust source with one model per
/// setting (heuristic-1 with a threshold table of its own, fitted on more plans) and a
/// held-out report, and refuses a bad argument with a clear message.
#[test]
fn calibrate_writes_models_and_a_held_out_report() {
    let out = scratch("calibrate");
    let rust = out.join("stop_calibration.rs");
    let o = activesense(&[
        "calibrate",
        "--agents",
        "heuristic-1,blind-0",
        "--rot-bins",
        "1,10",
        "--plans",
        "6",
        "--agent-tables",
        "heuristic-1",
        "--agent-table-plans",
        "10",
        "--no-progress",
        "--rust-out",
        s(&rust),
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let src = std::fs::read_to_string(&rust).unwrap();
    assert!(src.contains("pub const MODELS: &[StopModel]"), "{src}");
    assert_eq!(src.matches("StopModel {").count(), 2, "{src}");
    assert!(src.contains("rot_bins: 1,") && src.contains("rot_bins: 10,"));
    assert!(src.contains("Generated by `activesense calibrate"));
    assert_eq!(
        src.matches("agent: AgentKind::Heuristic1,").count(),
        2,
        "one own table per setting: {src}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap())
            .unwrap();
    for fitted in json.as_array().unwrap() {
        let w = fitted["model"]["weights"].as_array().unwrap();
        assert!(w.iter().all(|x| x.as_f64().is_some_and(f64::is_finite)));
        assert!(fitted["fit_samples"].as_u64().unwrap() > 0);
    }
    let md = std::fs::read_to_string(out.join("calibration.md")).unwrap();
    assert!(md.contains("## K = 1") && md.contains("## K = 10") && md.contains("episodes stopped"));
    // Its own table: placed on all 10 plans (those with a decision point), and each of
    // them checked once by the cross-fit (the other half's table).
    assert!(md.contains("heuristic-1's own table"), "{md}");
    assert!(md.contains("checked by cross-fitting"), "{md}");
    let own = &json[0]["held_out"]["agents"][0];
    assert_eq!(own["agent"], "heuristic-1");
    let placed_on = own["fit_episodes"].as_u64().unwrap();
    assert!((1..=10).contains(&placed_on), "{own}");
    assert_eq!(own["episodes"].as_u64().unwrap(), placed_on);

    let bad = activesense(&["calibrate", "--plans", "1", "--rust-out", s(&rust)]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--plans must be at least 2"));
    let bad = activesense(&[
        "calibrate",
        "--agents",
        "heuristic-1",
        "--rust-out",
        s(&rust),
    ]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("--agent-tables") && err.contains("not among --agents"),
        "{err}"
    );
}
