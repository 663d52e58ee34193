//! What the instrument answers, through the binary: `episode --plan` on a
//! national-grid JSON and on a millimetre DXF gives the station in the file's coordinates
//! and units, checked against poses computed here by hand; a symmetric room with the
//! heading unknown is ambiguous with both twins, and `--heading-hint` resolves it; a hall
//! the EDM cannot span is refused when loaded; `sim` prints the same answer.

mod common;
use common::{activesense, s, scratch};
use serde_json::Value;
use std::path::Path;

/// National-grid offsets of the test rooms (Swiss LV95-like, metres).
const E0: f64 = 2_600_123.0;
const N0: f64 = 1_200_456.0;

/// Runs `episode` with `args`, returning stdout and the `--answer-json` and `--json` files.
fn episode(dir: &Path, args: &[&str]) -> (String, Value, Value) {
    let answer = dir.join("answer.json");
    let traj = dir.join("trajectory.json");
    let mut all = vec!["episode", "--quiet"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--answer-json", s(&answer), "--json", s(&traj)]);
    let out = activesense(&all);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read =
        |p: &Path| -> Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let t = read(&traj);
    let a = read(&answer);
    assert_eq!(t["answer"], a, "--json embeds the same answer");
    (stdout, a, t)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// Every field the issue asks of the JSON answer.
fn has_fields(a: &Value) {
    for k in [
        "easting",
        "northing",
        "heading_deg",
        "heading_gon",
        "sigma_e",
        "sigma_n",
        "sigma_heading_deg",
        "candidates",
        "ambiguous",
    ] {
        assert!(a.get(k).is_some(), "answer lacks {k}: {a}");
    }
    for c in a["candidates"].as_array().unwrap() {
        for k in [
            "easting",
            "northing",
            "heading_deg",
            "heading_gon",
            "probability",
        ] {
            assert!(c.get(k).is_some(), "candidate lacks {k}: {c}");
        }
    }
    let (d, g) = (f(&a["heading_deg"]), f(&a["heading_gon"]));
    assert!(
        ((d / 0.9).rem_euclid(400.0) - g).abs() < 1e-9,
        "{d}° vs {g} gon"
    );
}

/// A 12 × 8 m rectangle whose centre is at (E0, N0): its perimeter centroid, the model
/// origin, is that centre.
fn national_rect(dir: &Path) -> std::path::PathBuf {
    let p = dir.join("rect.json");
    let v: Vec<[f64; 2]> = [(-6.0, -4.0), (6.0, -4.0), (6.0, 4.0), (-6.0, 4.0)]
        .iter()
        .map(|&(x, y)| [E0 + x, N0 + y])
        .collect();
    std::fs::write(&p, serde_json::json!({ "vertices": v }).to_string()).unwrap();
    p
}

#[test]
fn national_grid_json_answers_in_its_own_coordinates() {
    let dir = scratch("answer-grid");
    let plan = national_rect(&dir);
    let (stdout, a, t) = episode(&dir, &["--plan", s(&plan)]);
    has_fields(&a);
    assert_eq!(a["unit"], "m");
    // By hand: the model frame is the file's shifted by the rectangle's centre.
    let (tx, ty, th) = (
        f(&t["truth"]["x"]),
        f(&t["truth"]["y"]),
        f(&t["truth"]["theta"]),
    );
    let truth = &a["truth"];
    assert!((f(&truth["easting"]) - (E0 + tx)).abs() < 1e-6, "{truth}");
    assert!((f(&truth["northing"]) - (N0 + ty)).abs() < 1e-6, "{truth}");
    assert!((f(&truth["heading_deg"]) - th.to_degrees()).abs() < 1e-4);
    // K = 1: the heading was given, one candidate, the station within 5 cm and within
    // four of its printed σ.
    assert_eq!(a["ambiguous"], false);
    assert_eq!(a["heading_given"], true);
    assert_eq!(a["candidates"].as_array().unwrap().len(), 1);
    let (de, dn) = (f(&a["easting"]) - (E0 + tx), f(&a["northing"]) - (N0 + ty));
    assert!(de.hypot(dn) < 0.05, "station {de}, {dn} m off");
    assert!(
        de.abs() < 4.0 * f(&a["sigma_e"]) && dn.abs() < 4.0 * f(&a["sigma_n"]),
        "{a}"
    );
    assert_eq!(f(&a["sigma_heading_deg"]), 0.0);
    // The refined model-frame pose plus the centre is the answer.
    let r = &t["outcome"]["refined"]["pose"];
    assert!((f(&a["easting"]) - (E0 + f(&r["x"]))).abs() < 1e-6);
    assert!(
        stdout.contains("station: E 26001") && stdout.contains("N 12004"),
        "{stdout}"
    );
    assert!(stdout.contains(" gon"), "{stdout}");
    // The benchmark's combined number says what it is.
    assert!(
        stdout.contains("position and heading in one number"),
        "{stdout}"
    );
}

#[test]
fn millimetre_dxf_answers_in_millimetres() {
    let dir = scratch("answer-dxf");
    // The L-room in millimetres, far from the origin.
    let room: [[f64; 2]; 6] = [
        [0.0, 0.0],
        [6.0, 0.0],
        [6.0, 3.0],
        [2.5, 3.0],
        [2.5, 5.0],
        [0.0, 5.0],
    ];
    let off = [E0 * 1000.0, N0 * 1000.0];
    let mut text = String::from(
        "0\nSECTION\n2\nHEADER\n9\n$INSUNITS\n70\n4\n0\nENDSEC\n0\nSECTION\n2\nENTITIES\n0\nLWPOLYLINE\n5\n20\n8\nWALLS\n100\nAcDbPolyline\n90\n6\n70\n1\n",
    );
    for p in room {
        text += &format!(
            "10\n{}\n20\n{}\n",
            p[0] * 1000.0 + off[0],
            p[1] * 1000.0 + off[1]
        );
    }
    text += "0\nENDSEC\n0\nEOF\n";
    let plan = dir.join("l-room-mm.dxf");
    std::fs::write(&plan, text).unwrap();
    // By hand: the perimeter centroid (length-weighted wall midpoints), in file mm.
    let (mut per, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for i in 0..6 {
        let (a, b) = (room[i], room[(i + 1) % 6]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        per += len;
        cx += len * 0.5 * (a[0] + b[0]);
        cy += len * 0.5 * (a[1] + b[1]);
    }
    let c = [cx / per * 1000.0 + off[0], cy / per * 1000.0 + off[1]];
    let (_, a, t) = episode(
        &dir,
        &[
            "--plan",
            s(&plan),
            "--rot-bins",
            "10",
            "--episode-seed",
            "1",
        ],
    );
    has_fields(&a);
    assert_eq!(a["unit"], "mm");
    let (tx, ty) = (f(&t["truth"]["x"]), f(&t["truth"]["y"]));
    let truth = &a["truth"];
    assert!(
        (f(&truth["easting"]) - (c[0] + 1000.0 * tx)).abs() < 0.05,
        "{truth}"
    );
    assert!(
        (f(&truth["northing"]) - (c[1] + 1000.0 * ty)).abs() < 0.05,
        "{truth}"
    );
    // The L-room has no symmetry: one candidate; the station within 50 mm.
    assert_eq!(a["ambiguous"], false);
    let (de, dn) = (
        f(&a["easting"]) - f(&truth["easting"]),
        f(&a["northing"]) - f(&truth["northing"]),
    );
    assert!(de.hypot(dn) < 50.0, "station {de}, {dn} mm off");
    // σ in millimetres, the heading estimated.
    assert!(f(&a["sigma_e"]) > 0.5 && f(&a["sigma_e"]) < 100.0, "{a}");
    assert!(f(&a["sigma_heading_deg"]) > 0.0);
}

#[test]
fn symmetric_room_is_ambiguous_until_the_heading_hint() {
    let dir = scratch("answer-sym");
    let plan = national_rect(&dir);
    let (stdout, a, t) = episode(&dir, &["--plan", s(&plan), "--rot-bins", "10"]);
    has_fields(&a);
    assert_eq!(a["ambiguous"], true, "{stdout}");
    assert!(stdout.contains("AMBIGUOUS: 2 poses"), "{stdout}");
    let c = a["candidates"].as_array().unwrap();
    assert_eq!(c.len(), 2);
    // By hand: the twins are turned by 180° about the rectangle's centre.
    assert!((f(&c[0]["easting"]) + f(&c[1]["easting"]) - 2.0 * E0).abs() < 1e-6);
    assert!((f(&c[0]["northing"]) + f(&c[1]["northing"]) - 2.0 * N0).abs() < 1e-6);
    let dh = (f(&c[0]["heading_deg"]) - f(&c[1]["heading_deg"])).rem_euclid(360.0);
    assert!((dh - 180.0).abs() < 1e-9, "{dh}");
    for k in c {
        assert!((f(&k["probability"]) - 0.5).abs() < 1e-12);
    }
    // The truth is one of them, within 5 cm.
    let (tx, ty, th) = (
        f(&t["truth"]["x"]),
        f(&t["truth"]["y"]),
        f(&t["truth"]["theta"]),
    );
    let near = c
        .iter()
        .map(|k| (f(&k["easting"]) - E0 - tx).hypot(f(&k["northing"]) - N0 - ty))
        .fold(f64::MAX, f64::min);
    assert!(near < 0.05, "no candidate within 5 cm: {near}");
    // A compass reading 10° off, ± 30°: one pose, the true one.
    let hint = format!("{:.1}±30", th.to_degrees() + 10.0);
    let (stdout, a, _) = episode(
        &dir,
        &[
            "--plan",
            s(&plan),
            "--rot-bins",
            "10",
            "--heading-hint",
            &hint,
        ],
    );
    assert_eq!(a["ambiguous"], false, "{stdout}");
    assert_eq!(a["candidates"].as_array().unwrap().len(), 1);
    assert!((f(&a["candidates"][0]["probability"]) - 1.0).abs() < 1e-12);
    let d = (f(&a["easting"]) - E0 - tx).hypot(f(&a["northing"]) - N0 - ty);
    assert!(d < 0.05, "the hint kept the wrong twin: {d} m");
    assert!(stdout.contains("resolved by the heading hint"), "{stdout}");
    assert!(!stdout.contains("AMBIGUOUS"), "{stdout}");
    // A bad hint is a one-line usage error.
    let out = activesense(&["episode", "--plan", s(&plan), "--heading-hint", "north"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("is not a heading hint"));
}

#[test]
fn rooms_the_instrument_cannot_localize_in_are_refused_when_loaded() {
    let dir = scratch("answer-admissible");
    for (name, w, h, want) in [
        ("hall.json", 120.0, 80.0, "too large for the EDM"),
        ("sliver.json", 10.0, 0.6, "0.60 m wide"),
    ] {
        let p = dir.join(name);
        let v = [[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]];
        std::fs::write(&p, serde_json::json!({ "vertices": v }).to_string()).unwrap();
        let out = activesense(&["episode", "--plan", s(&p)]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name} accepted");
        let line = err.lines().find(|l| l.starts_with("error: ")).unwrap_or("");
        assert!(line.contains(name) && line.contains(want), "{err}");
    }
}

#[test]
fn sim_prints_the_answer_in_plan_coordinates() {
    let dir = scratch("answer-sim");
    let plan = national_rect(&dir);
    let out = activesense(&[
        "sim",
        "--link",
        "loopback",
        "--plan",
        s(&plan),
        "--episodes",
        "1",
        "--rot-bins",
        "10",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("  answer (the plan file's own coordinates"),
        "{stdout}"
    );
    assert!(stdout.contains("station: E 26001"), "{stdout}");
    assert!(stdout.contains("AMBIGUOUS: 2 poses"), "{stdout}");
}
