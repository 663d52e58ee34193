//! The user's own floor plans through the binary (`docs/PLANS.md`): every format plays the
//! same known room, every malformed file gives its documented one-line error naming the
//! file, a directory with a bad file evaluates the good ones and lists the bad one, and
//! `sim` prints the pose error per episode.

mod common;
use common::{activesense, s, scratch};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/plans")
        .join(name)
}

/// The plan vertices of `episode --plan FILE --json`.
fn plan_of(dir: &Path, file: &Path, extra: &[&str]) -> Vec<[f64; 2]> {
    let json = dir.join(format!(
        "{}.json",
        file.file_name().unwrap().to_str().unwrap()
    ));
    let mut args = vec!["episode", "--plan", s(file), "--quiet", "--json", s(&json)];
    args.extend_from_slice(extra);
    let out = activesense(&args);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("refined estimate: ("), "{stdout}");
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    serde_json::from_value(t["plan"]["vertices"].clone()).unwrap()
}

#[test]
fn each_format_plays_the_same_l_room() {
    let dir = scratch("plans-formats");
    // The L-room in metres, centred on its perimeter centroid (the model frame).
    let room: [[f64; 2]; 6] = [
        [0.0, 0.0],
        [6.0, 0.0],
        [6.0, 3.0],
        [2.5, 3.0],
        [2.5, 5.0],
        [0.0, 5.0],
    ];
    let edges: Vec<(f64, [f64; 2])> = (0..6)
        .map(|i| {
            let (a, b) = (room[i], room[(i + 1) % 6]);
            let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            (len, [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])])
        })
        .collect();
    let per: f64 = edges.iter().map(|e| e.0).sum();
    let c = [
        edges.iter().map(|e| e.0 * e.1[0]).sum::<f64>() / per,
        edges.iter().map(|e| e.1[1] * e.0).sum::<f64>() / per,
    ];
    let centred: Vec<[f64; 2]> = room.iter().map(|p| [p[0] - c[0], p[1] - c[1]]).collect();
    for (file, extra) in [
        ("l-room.json", &[][..]),
        ("l-room.geojson", &[][..]),
        ("l-room.dxf", &[][..]),
        ("offices.geojson", &["--room", "office-2"][..]),
    ] {
        let got = plan_of(&dir, &fixture(file), extra);
        if file == "offices.geojson" {
            // The second room of the collection: 6 outline vertices, then its hole, a
            // column of 4.
            assert_eq!(got.len(), 10, "{file}: {got:?}");
            continue;
        }
        assert_eq!(got.len(), 6, "{file}: {got:?}");
        let start = got
            .iter()
            .position(|p| {
                (p[0] - centred[0][0]).abs() < 1e-4 && (p[1] - centred[0][1]).abs() < 1e-4
            })
            .unwrap_or_else(|| panic!("{file}: {got:?} vs {centred:?}"));
        for i in 0..6 {
            let (g, e) = (got[(start + i) % 6], centred[i]);
            assert!(
                (g[0] - e[0]).abs() < 1e-4 && (g[1] - e[1]).abs() < 1e-4,
                "{file} vertex {i}: {g:?} vs {e:?}"
            );
        }
    }
}

/// Runs `episode --plan FILE` expecting the documented one-line error.
fn refused(file: &Path, extra: &[&str], want: &[&str]) {
    let mut args = vec!["episode", "--plan", s(file)];
    args.extend_from_slice(extra);
    let out = activesense(&args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{file:?} accepted");
    assert!(!err.contains("panicked"), "{err}");
    let line = err
        .lines()
        .find(|l| l.starts_with("error: "))
        .unwrap_or_else(|| panic!("no error line: {err}"));
    assert!(
        line.starts_with(&format!("error: {}", file.display())),
        "does not name the file: {line}"
    );
    for w in want {
        assert!(line.contains(w), "'{w}' missing from: {line}");
    }
}

fn dxf(polys: &[(&str, &[[f64; 2]], bool)], extra_entities: &str) -> String {
    let mut t = String::from("0\nSECTION\n2\nENTITIES\n");
    for (h, (layer, pts, closed)) in polys.iter().enumerate() {
        t += &format!(
            "0\nLWPOLYLINE\n5\n{:X}\n8\n{layer}\n100\nAcDbPolyline\n90\n{}\n70\n{}\n",
            0x40 + h,
            pts.len(),
            *closed as u8
        );
        for p in pts.iter() {
            t += &format!("10\n{}\n20\n{}\n", p[0], p[1]);
        }
    }
    t + extra_entities + "0\nENDSEC\n0\nEOF\n"
}

#[test]
fn malformed_files_give_the_documented_errors() {
    let dir = scratch("plans-bad");
    let w = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let rect: &[[f64; 2]] = &[[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]];
    refused(&w("garbage.json", "vertices: 1"), &[], &["not valid JSON"]);
    refused(
        &w("novert.json", r#"{"points": [[0, 0]]}"#),
        &[],
        &["no \"vertices\" member"],
    );
    refused(
        &w(
            "pair.json",
            r#"{"vertices": [[0, 0], [4, 0], [4], [0, 3]]}"#,
        ),
        &[],
        &["vertex 2 is not an [x, y] pair"],
    );
    refused(
        &w(
            "bow.json",
            r#"{"vertices": [[0, 0], [4, 0], [0, 3], [4, 3]]}"#,
        ),
        &[],
        &["crosses itself", "edge 1–2 (4, 0) → (0, 3)", "edge 3–0"],
    );
    refused(
        &w("two.json", r#"{"vertices": [[0, 0], [4, 0], [0, 0]]}"#),
        &[],
        &["2 distinct vertices; a room needs at least 3"],
    );
    let star: Vec<[f64; 2]> = (0..70)
        .map(|i| {
            let a = i as f64 * std::f64::consts::TAU / 70.0;
            let r = if i % 2 == 0 { 5.0 } else { 4.0 };
            [r * a.cos(), r * a.sin()]
        })
        .collect();
    refused(
        &w(
            "star.json",
            &serde_json::json!({ "vertices": star }).to_string(),
        ),
        &[],
        &["70 vertices; a room may have at most 64"],
    );
    refused(
        &w(
            "dup.json",
            r#"{"vertices": [[0, 0], [4, 0], [4, 0.001], [4, 3], [0, 3]]}"#,
        ),
        &[],
        &["edge 1–2 (4, 0) → (4, 0.001) is shorter than 1 cm"],
    );
    refused(
        &w(
            "mm.json",
            r#"{"vertices": [[0, 0], [4000, 0], [4000, 3000], [0, 3000]]}"#,
        ),
        &[],
        &["4000.000 m × 3000.000 m", "try --units mm"],
    );
    refused(
        &w(
            "lonlat.geojson",
            r#"{"type": "Polygon", "coordinates": [[[8.54, 47.37], [8.5401, 47.37], [8.5401, 47.3701], [8.54, 47.3701], [8.54, 47.37]]]}"#,
        ),
        &[],
        &["longitude/latitude degrees are not supported"],
    );
    refused(
        &w(
            "line.geojson",
            r#"{"type": "Feature", "properties": {}, "geometry": {"type": "LineString", "coordinates": [[0, 0], [4, 0]]}}"#,
        ),
        &[],
        &["geometry type LineString: a room must be a Polygon"],
    );
    refused(
        &w(
            "multi.geojson",
            r#"{"type": "MultiPolygon", "coordinates": []}"#,
        ),
        &[],
        &["MultiPolygon", "split"],
    );
    refused(
        &w(
            "fc.geojson",
            r#"{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"name": "hall"}, "geometry": {"type": "Point", "coordinates": [0, 0]}}]}"#,
        ),
        &[],
        &["(feature 0 'hall')", "geometry type Point"],
    );
    refused(
        &fixture("offices.geojson"),
        &[],
        &["holds 2 rooms", "--room"],
    );
    refused(
        &fixture("offices.geojson"),
        &["--room", "kitchen"],
        &["no room 'kitchen'"],
    );
    refused(
        &w("open.dxf", &dxf(&[("WALLS", rect, false)], "")),
        &[],
        &["LWPOLYLINE 40 on layer 'WALLS' is open"],
    );
    refused(
        &w(
            "lines.dxf",
            &dxf(&[], "0\nLINE\n8\nWALLS\n10\n0\n20\n0\n11\n4\n21\n0\n"),
        ),
        &[],
        &["no LWPOLYLINE or POLYLINE entity"],
    );
    let layers = w(
        "layers.dxf",
        &dxf(&[("WALLS", rect, true), ("FURNITURE", rect, true)], ""),
    );
    refused(
        &layers,
        &[],
        &[
            "closed polylines on several layers (FURNITURE, WALLS)",
            "--layer",
        ],
    );
    refused(
        &layers,
        &["--layer", "ROOF"],
        &["no polyline on layer 'ROOF'"],
    );
    let arc = dxf(&[("WALLS", rect, true)], "").replacen("20\n0\n", "20\n0\n42\n1\n", 1);
    refused(
        &w("arc.dxf", &arc),
        &[],
        &["vertex 0 starts an arc (bulge)"],
    );
    refused(
        &w("junk.dxf", "this is not a drawing\n"),
        &[],
        &["not a readable DXF file"],
    );
    refused(&w("room.txt", "{}"), &[], &["unknown plan format"]);
    refused(&dir.join("missing.json"), &[], &["cannot read"]);
    // `serial run` reads its plan with the same loader, before it opens the port.
    let out = activesense(&[
        "serial",
        "run",
        "--port",
        "/nonexistent/tty",
        "--plan",
        s(&dir.join("bow.json")),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with(&format!(
            "error: {}: the outline crosses itself",
            dir.join("bow.json").display()
        )),
        "{err}"
    );
    // The layer option picks one of the candidates, and the units option scales.
    let out = activesense(&[
        "episode",
        "--plan",
        s(&layers),
        "--layer",
        "WALLS",
        "--quiet",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = activesense(&[
        "episode",
        "--plan",
        s(&dir.join("mm.json")),
        "--units",
        "mm",
        "--quiet",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn eval_plans_from_a_directory_skips_and_lists_the_bad_file() {
    let dir = scratch("plans-eval");
    let plans = dir.join("rooms");
    std::fs::create_dir_all(&plans).unwrap();
    for f in ["l-room.json", "l-room.dxf", "offices.geojson"] {
        std::fs::copy(fixture(f), plans.join(f)).unwrap();
    }
    std::fs::write(plans.join("bad.json"), r#"{"vertices": [[0, 0], [1, 0]]}"#).unwrap();
    std::fs::write(plans.join("README.txt"), "not a plan").unwrap();
    let out_dir = dir.join("out");
    // Every kind of agent plays the user's rooms: a baseline, the float and int8 learnt
    // policies, and the greedy benchmarks (which rebuild the room from the spec).
    let eval = |out_dir: &Path| {
        activesense(&[
            "eval",
            "--plans-from",
            s(&plans),
            "--agents",
            "heuristic-1,learnt,learnt-int8,oigm,eem",
            "--rot-bins",
            "1",
            "--curve-plans",
            "1",
            "--no-progress",
            "--out",
            s(out_dir),
        ])
    };
    let out = eval(&out_dir);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    // Deterministic: a second run writes the same results.json.
    let again = dir.join("again");
    assert!(eval(&again).status.success());
    assert_eq!(
        std::fs::read(out_dir.join("results.json")).unwrap(),
        std::fs::read(again.join("results.json")).unwrap()
    );
    assert!(
        err.contains(&format!("refused: {}", plans.join("bad.json").display())),
        "{err}"
    );
    assert!(err.contains("4 room(s) loaded, 1 file(s) refused"), "{err}");
    // office-2's hole is a column, read without a warning.
    assert!(!err.contains("hole(s) ignored"), "{err}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("results.json")).unwrap())
            .unwrap();
    let groups = r["results"].as_array().unwrap();
    assert_eq!(groups.len(), 5);
    for g in groups {
        assert_eq!(g["plans"], 4);
        // Every episode ran in the user's room (a generated plan would not carry its name)
        // and produced an estimate.
        assert_eq!(g["unregistered"], 0, "{}", g["agent"]);
        let names: Vec<&str> = g["episodes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["plan"].as_str().unwrap())
            .collect();
        assert_eq!(
            names,
            [
                "l-room.dxf",
                "l-room.json",
                "offices.geojson#office-1",
                "offices.geojson#office-2"
            ]
        );
    }
    let md = std::fs::read_to_string(out_dir.join("results.md")).unwrap();
    assert!(md.contains("4 user plans (l-room.dxf, l-room.json"), "{md}");
    assert!(md.contains("bad.json: 2 distinct vertices"), "{md}");
    for f in ["budget.svg", "utility-k1.svg", "timing.json"] {
        assert!(out_dir.join(f).exists(), "{f}");
    }
}

#[test]
fn sim_prints_the_pose_error_of_every_episode() {
    let out = activesense(&[
        "sim",
        "--link",
        "loopback",
        "--plan",
        s(&fixture("l-room.dxf")),
        "--episodes",
        "2",
        "--verify",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for i in 0..2 {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&format!("l-room.dxf episode {i}:")))
            .unwrap_or_else(|| panic!("{stdout}"));
        assert!(line.contains(", pose error 0."), "{line}");
    }
    assert!(
        stdout.contains("pose error against the simulated truth: mean"),
        "{stdout}"
    );
}
