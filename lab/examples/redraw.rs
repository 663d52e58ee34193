//! Every committed chart drawn again from the JSON it was drawn from
//! (`activesense_lab::eval::redraw`): `results/` and `policies/` by default.
//!
//! `cargo run --release -p activesense-lab --example redraw -- [--check] [DIR ...]`
//!
//! With `--check`, nothing is written: every chart that would change is listed, and the
//! exit status is 1 if any would (`cargo xtask reproduce --check` runs this).

use activesense_lab::eval::redraw::{chart_dirs, charts_of};
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let check = args.iter().any(|a| a == "--check");
    let mut roots: Vec<PathBuf> = args
        .iter()
        .filter(|a| *a != "--check")
        .map(PathBuf::from)
        .collect();
    if roots.is_empty() {
        roots = vec!["results".into(), "policies".into()];
    }
    let (mut written, mut stale) = (0, Vec::new());
    for root in &roots {
        for dir in chart_dirs(root)? {
            for (name, svg) in charts_of(&dir)? {
                let path = dir.join(&name);
                if std::fs::read_to_string(&path).ok().as_deref() == Some(svg.as_str()) {
                    continue;
                }
                if check {
                    stale.push(path.display().to_string());
                } else {
                    std::fs::write(&path, svg)?;
                    written += 1;
                }
            }
        }
    }
    if check {
        if !stale.is_empty() {
            eprintln!(
                "charts not drawn by the current code:\n  {}",
                stale.join("\n  ")
            );
            std::process::exit(1);
        }
        eprintln!("every chart is current");
    } else {
        eprintln!("redrew {written} chart(s)");
    }
    Ok(())
}
