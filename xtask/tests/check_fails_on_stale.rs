//! `cargo xtask reproduce --check` against a doctored copy of the committed artifacts: a stale
//! int8 blob and a results file whose fourth episode moved must both be reported (and the
//! untouched blob must not), and the same copy with the originals put back must pass. Without
//! this test a `--check` that compared nothing would look exactly like one that passes.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn copy(rel: &str, to: &Path) {
    let dst = to.join(rel);
    std::fs::create_dir_all(dst.parent().unwrap()).unwrap();
    std::fs::copy(root().join(rel), dst).unwrap();
}

fn check(artifacts: &Path) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args([
            "reproduce",
            "--check",
            "--only",
            "int8-k1,int8-k10,eval-ablation-k1-no-scans",
            "--artifacts",
        ])
        .arg(artifacts)
        .current_dir(root())
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const BLOB_K1: &str = "policies/k1/policy.q8";
const BLOB_K10: &str = "policies/k10/policy.q8";
const RESULTS: &str = "results/ablations/k1-no-scans/results.json";

#[test]
fn a_stale_blob_and_a_moved_episode_fail_the_check() {
    let tmp = std::env::temp_dir().join(format!("activesense-check-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    for rel in [BLOB_K1, BLOB_K10, RESULTS] {
        copy(rel, &tmp);
    }

    // A blob with one byte changed, and an episode whose cost moved.
    let blob = tmp.join(BLOB_K10);
    let mut bytes = std::fs::read(&blob).unwrap();
    bytes[100] ^= 1;
    std::fs::write(&blob, bytes).unwrap();
    let path = tmp.join(RESULTS);
    let mut results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let cost = &mut results["results"][0]["episodes"][3]["cost"];
    *cost = serde_json::json!(cost.as_f64().unwrap() + 0.005);
    std::fs::write(&path, serde_json::to_string_pretty(&results).unwrap()).unwrap();

    let (ok, stderr) = check(&tmp);
    assert!(!ok, "--check passed on doctored artifacts:\n{stderr}");
    assert!(
        stderr.contains(BLOB_K10),
        "the stale blob is not named:\n{stderr}"
    );
    assert!(
        !stderr.contains(&format!("{BLOB_K1} (step")),
        "the good blob is named:\n{stderr}"
    );
    assert!(
        stderr.contains(
            "results/ablations/k1-no-scans/results.json (step eval-ablation-k1-no-scans)"
        ) && stderr.contains("episode 3"),
        "the moved episode is not named:\n{stderr}"
    );

    // The originals back: the same check passes.
    for rel in [BLOB_K10, RESULTS] {
        copy(rel, &tmp);
    }
    let (ok, stderr) = check(&tmp);
    assert!(ok, "--check failed on the committed artifacts:\n{stderr}");
    let _ = std::fs::remove_dir_all(&tmp);
}
