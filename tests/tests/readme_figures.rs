//! The README's and the guide's tables against the files they come from: a figure cannot drift
//! from its committed result without this test failing. The README keeps the headline
//! tables (the no-oracle table and Table 4), checked there and in `docs/results.md`; every other
//! table lives in `docs/results.md` and is checked there: the "ours" rows of Table 4 against
//! `results/results.json`, the greedy, greedy-confident and ablation tables against their runs, the
//! int8 agreement table against `results/policy-agreement.json`, the Fig.-4 table against
//! `docs/inspect/k{1,10}/aggregate.md`, the calibrated-stop table against
//! `results/confident/results.json`, the no-oracle table against `results/no-oracle/results.json`,
//! the frontier against `results/frontier/frontier.json`, the four MCU tables against
//! `results/mcu-bench/*.md` (verbatim), and the size table against `results/size.md`. The README
//! itself stays a short user's guide: at most 250 lines, no commit hashes, no issue numbers.

use serde_json::Value;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Where the headline tables live: the README and the guide's results page.
const HEADLINE_FILES: [&str; 2] = ["README.md", "docs/results.md"];
/// Where every other table lives.
const RESULTS: &str = "docs/results.md";
/// The headline tables' headings, the same in both files. The no-oracle table is labelled with its
/// instrument profile, so a second profile's table (EDM only) can sit beside it under its own.
const NO_ORACLE: &str = "### Without an oracle: EDM + topological scan (the paper's sensor)";
/// The EDM-only instrument's no-oracle table (what GeoCOM total stations are): first.
const NO_ORACLE_EDM: &str = "### Without an oracle: EDM only (the total stations surveyors own)";
const TABLE_4: &str = "### Table 4: the paper's and ours (oracle stop)";

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn json(rel: &str) -> Value {
    serde_json::from_str(&read(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The result row of `agent` at `k` rotation bins.
fn row<'a>(results: &'a Value, agent: &str, k: u64) -> &'a Value {
    results["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["agent"] == agent && r["rot_bins"] == k)
        .unwrap_or_else(|| panic!("no row {agent} K = {k}"))
}

fn f(r: &Value, key: &str) -> f64 {
    r[key].as_f64().unwrap_or_else(|| panic!("{key} missing"))
}

/// Cells of a markdown table row (`| a | b |` → `["a", "b"]`).
fn cells(line: &str) -> Vec<String> {
    line.trim()
        .trim_matches('|')
        .split('|')
        .map(|c| c.trim().replace("**", ""))
        .collect()
}

/// The rows (as cells) of the first table after `heading` in `text` whose header row starts
/// with `header`, header and rule left out.
fn table_at(text: &str, heading: &str, header: &str) -> Vec<Vec<String>> {
    let at = text
        .find(heading)
        .unwrap_or_else(|| panic!("no section {heading}"));
    text[at..]
        .lines()
        .skip_while(|l| !l.starts_with(header))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(cells)
        .collect()
}

/// [`table_at`] for the usual `| agent | …` tables.
fn table_after(text: &str, heading: &str) -> Vec<Vec<String>> {
    table_at(text, heading, "| agent")
}

#[test]
fn table_4_ours_rows_are_the_main_job() {
    for file in HEADLINE_FILES {
        table_4_ours_rows_are_the_main_job_in(file);
    }
}

fn table_4_ours_rows_are_the_main_job_in(file: &str) {
    let readme = read(file);
    let results = json("results/results.json");
    let mut agent = String::new();
    let mut checked = 0;
    for c in table_after(&readme, TABLE_4) {
        if !c[0].is_empty() {
            agent = c[0].clone();
        }
        let name = match (agent.as_str(), c[1].as_str()) {
            (_, "paper") => continue,
            ("learnt policy", "ours (float)") => "learnt".to_string(),
            ("learnt policy", _) => "learnt-int8".to_string(),
            (a, _) => a.to_string(),
        };
        let (k1, k10) = (row(&results, &name, 1), row(&results, &name, 10));
        let columns = [
            ("recognition_rate", 3),
            ("pose_error", 4),
            ("measurements", 3),
            ("rotations", 3),
            ("cost", 3),
        ];
        for ((key, digits), cell) in columns.iter().zip(&c[2..]) {
            let want = format!(
                "{:.d$} ({:.d$})",
                f(k1, key),
                f(k10, key),
                d = *digits as usize
            );
            assert_eq!(cell, &want, "{file} Table 4, {name}, {key}");
        }
        checked += 1;
    }
    assert!(
        checked >= 9,
        "only {checked} 'ours' rows found in {file}'s Table 4"
    );
}

#[test]
fn the_calibrated_stop_table_is_results_confident() {
    let readme = read(RESULTS);
    let confident = json("results/confident/results.json");
    let main = json("results/results.json");
    let greedy = json("results/greedy/results.json");
    let mut checked = 0;
    for c in table_after(
        &readme,
        "## Stopping without ground truth: the calibrated stop",
    ) {
        let line = c.join(" | ");
        let k: u64 = c[1].parse().unwrap();
        let r = row(&confident, &c[0], k);
        let oracle = if c[0] == "eem" {
            row(&greedy, "eem", k)
        } else {
            row(&main, &c[0], k)
        };
        assert_eq!(
            c[2],
            format!(
                "{} ({})",
                fixed(r, "recognition_rate", 3),
                fixed(oracle, "recognition_rate", 3)
            ),
            "{line}"
        );
        assert_eq!(
            c[3],
            format!("{:.3}", f(r, "answered") / f(r, "plans")),
            "{line}"
        );
        assert_eq!(c[4], fixed(r, "right", 3), "{line}");
        let wrong = f(r, "wrong");
        assert_eq!(
            c[5],
            format!("{wrong} ({:.1} %)", 100.0 * f(r, "wrong_of_answered")),
            "{line}"
        );
        assert_eq!(
            c[6],
            format!("{:.2} %", 100.0 * f(r, "mean_risk_at_stop")),
            "{line}"
        );
        assert_eq!(c[7], fixed(r, "pose_error", 4), "{line}");
        assert_eq!(c[8], fixed(r, "measurements", 2), "{line}");
        assert_eq!(c[9], fixed(r, "cost", 3), "{line}");
        checked += 1;
    }
    assert!(
        checked >= 6,
        "only {checked} rows found in the calibrated-stop table"
    );
}

/// The no-oracle table, in the README and in the guide's results page: every agent,
/// K = 1 and 10, stopping by itself, from the main job's `results/no-oracle/results.json`.
#[test]
fn the_no_oracle_table_is_the_main_jobs() {
    for file in HEADLINE_FILES {
        the_no_oracle_table_is_the_main_jobs_in(file, NO_ORACLE, "results/no-oracle/results.json");
        the_no_oracle_table_is_the_main_jobs_in(
            file,
            NO_ORACLE_EDM,
            "results/no-oracle-edm/results.json",
        );
    }
    // Above the fold: first of the headline tables in the README, the EDM-only instrument's
    // first of all (what ships to GeoCOM users), and in the results page before the greedy
    // benchmarks.
    let readme = read("README.md");
    let edm = readme
        .find(NO_ORACLE_EDM)
        .expect("README has the EDM-only no-oracle section");
    let at = readme
        .find(NO_ORACLE)
        .expect("README has the no-oracle section");
    assert!(edm < at && at < readme.find(TABLE_4).expect("README has Table 4"));
    let results_page = read(RESULTS);
    let at = results_page.find(NO_ORACLE).unwrap();
    assert!(at < results_page.find("## Greedy benchmarks").unwrap());
}

fn the_no_oracle_table_is_the_main_jobs_in(file: &str, heading: &str, results: &str) {
    let readme = read(file);
    let results = json(results);
    assert!(readme.contains(heading), "{file} has the section {heading}");
    let mm = |r: &Value, key: &str| {
        r[key]
            .as_f64()
            .map(|x| format!("{:.1}", 1000.0 * x))
            .unwrap_or_else(|| "–".into())
    };
    let mut checked = 0;
    for c in table_after(&readme, heading) {
        let line = c.join(" | ");
        let k: u64 = c[1].parse().unwrap();
        let r = row(&results, &c[0], k);
        assert_eq!(c[2], fixed(r, "right", 3), "{line}");
        assert_eq!(
            c[3],
            format!(
                "{} ({:.1} %)",
                f(r, "wrong"),
                100.0 * f(r, "wrong_of_answered")
            ),
            "{line}"
        );
        assert_eq!(c[4], fixed(r, "unanswered", 3), "{line}");
        assert_eq!(c[5], fixed(r, "measurements", 2), "{line}");
        assert_eq!(c[6], fixed(r, "rotations", 2), "{line}");
        assert_eq!(c[7], fixed(r, "cost", 3), "{line}");
        assert_eq!(
            c[8],
            format!(
                "{} / {} / {}",
                mm(r, "right_position_error"),
                mm(r, "right_position_error_median"),
                mm(r, "right_position_error_p95")
            ),
            "{line}"
        );
        assert_eq!(c[9], fixed(r, "recognition_rate", 3), "{line}");
        checked += 1;
    }
    assert_eq!(checked, 18, "{file}: nine agents, K = 1 and 10");
}

/// The EDM-only instrument's agents room by room: one column group per site level (the room
/// as its plan, furnished, a building site), from the main job's `results/no-oracle-edm*/`.
const NO_ORACLE_SITES: &str = "### Without an oracle, in rooms that are not their plans (EDM only)";

#[test]
fn the_site_level_table_is_the_main_jobs() {
    let levels = [
        json("results/no-oracle-edm/results.json"),
        json("results/no-oracle-edm-furnished/results.json"),
        json("results/no-oracle-edm-site/results.json"),
    ];
    for file in HEADLINE_FILES {
        let text = read(file);
        assert!(
            text.contains(NO_ORACLE_SITES),
            "{file} has {NO_ORACLE_SITES}"
        );
        let mut checked = 0;
        for c in table_after(&text, NO_ORACLE_SITES) {
            let line = c.join(" | ");
            let k: u64 = c[1].parse().unwrap();
            for (g, results) in levels.iter().enumerate() {
                let r = row(results, &c[0], k);
                let at = 2 + 4 * g;
                assert_eq!(c[at], fixed(r, "right", 3), "{line}");
                assert_eq!(
                    c[at + 1],
                    format!(
                        "{} ({:.1} %)",
                        f(r, "wrong"),
                        100.0 * f(r, "wrong_of_answered")
                    ),
                    "{line}"
                );
                assert_eq!(c[at + 2], fixed(r, "unanswered", 3), "{line}");
                assert_eq!(c[at + 3], fixed(r, "cost", 3), "{line}");
            }
            checked += 1;
        }
        assert_eq!(
            checked, 6,
            "{file}: learnt, learnt-int8, heuristic-1 at K = 1 and 10"
        );
        // Right after the EDM-only table, before the paper's sensor's.
        let (edm, sites, paper) = (
            text.find(NO_ORACLE_EDM).unwrap(),
            text.find(NO_ORACLE_SITES).unwrap(),
            text.find(NO_ORACLE).unwrap(),
        );
        assert!(
            edm < sites && sites < paper,
            "{file}: the site table's place"
        );
    }
}

/// The frontier table (`docs/results.md`): per agent and K, cost and observed wrong answers at every
/// `--stop-risk` setting of `results/frontier/frontier.json`.
#[test]
fn the_frontier_table_is_results_frontier() {
    let readme = read(RESULTS);
    let fr = json("results/frontier/frontier.json");
    let risks: Vec<f64> = fr["stop_risks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let at = readme
        .find("## The risk–cost frontier")
        .expect("frontier section");
    let rows = table_at(&readme[at..], "", "| agent | K |");
    let mut checked = 0;
    for c in rows {
        let k: u64 = c[1].parse().unwrap();
        for (i, &p) in risks.iter().enumerate() {
            let pt = fr["points"]
                .as_array()
                .unwrap()
                .iter()
                .find(|q| {
                    q["agent"] == c[0].as_str()
                        && q["rot_bins"] == k
                        && (q["stop_risk"].as_f64().unwrap() - p).abs() < 1e-9
                })
                .unwrap_or_else(|| panic!("no frontier point {} K = {k} P = {p}", c[0]));
            let want = format!(
                "{:.3} / {:.1} %",
                f(pt, "cost"),
                100.0 * f(pt, "wrong_of_answered")
            );
            assert_eq!(c[2 + i], want, "frontier {} K = {k} P = {p}", c[0]);
        }
        checked += 1;
    }
    assert_eq!(checked, 6, "three agents, K = 1 and 10");
}

#[test]
fn the_mcu_tables_are_the_committed_benchmark_output() {
    let readme = read(RESULTS);
    for file in [
        "results/mcu-bench/heuristic-1-oracle.md",
        "results/mcu-bench/learnt-int8-oracle.md",
        "results/mcu-bench/heuristic-1-confident.md",
        "results/mcu-bench/learnt-int8-confident.md",
        "results/mcu-bench/learnt-int8-confident-edm.md",
    ] {
        let text = read(file);
        let rows: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with("| 1") || l.starts_with("| 10"))
            .collect();
        assert_eq!(rows.len(), 2, "{file}: expected a K = 1 and a K = 10 row");
        for r in rows {
            assert!(
                readme.contains(r),
                "{RESULTS} lacks this row of {file}:\n{r}"
            );
        }
    }
}

#[test]
fn the_size_table_is_results_size() {
    let readme = read(RESULTS);
    let size = read("results/size.md");
    let number = |prefix: &str| -> u64 {
        let line = size.lines().find(|l| l.starts_with(prefix)).unwrap();
        line[prefix.len()..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let with_commas = |n: u64| {
        let s = n.to_string();
        let mut out = String::new();
        for (i, ch) in s.chars().enumerate() {
            if i > 0 && (s.len() - i).is_multiple_of(3) {
                out.push(',');
            }
            out.push(ch);
        }
        out
    };
    for (prefix, what) in [("flash: ", "flash"), ("static RAM: ", "static RAM")] {
        let n = with_commas(number(prefix));
        let line = readme
            .lines()
            .find(|l| l.starts_with(&format!("| {what} (")))
            .unwrap_or_else(|| panic!("{RESULTS} has no {what} row"));
        assert!(
            line.contains(&n),
            "{RESULTS}'s {what} row lacks {n} (results/size.md):\n{line}"
        );
    }
}

/// `format!("{:.d$}")` of a result field.
fn fixed(r: &Value, key: &str, digits: usize) -> String {
    format!("{:.digits$}", f(r, key))
}

#[test]
fn the_greedy_table_is_results_greedy() {
    let readme = read(RESULTS);
    let greedy = json("results/greedy/results.json");
    let main = json("results/results.json");
    let mut checked = 0;
    for c in table_after(&readme, "## Greedy benchmarks (paper §4.3)") {
        let k: u64 = c[1].parse().unwrap();
        let r = match c[0].as_str() {
            "learnt (main job)" => row(&main, "learnt", k),
            agent => row(&greedy, agent, k),
        };
        let line = c.join(" | ");
        assert_eq!(c[2], fixed(r, "recognition_rate", 3), "{line}");
        assert_eq!(c[3], fixed(r, "pose_error", 4), "{line}");
        assert_eq!(c[4], fixed(r, "measurements", 2), "{line}");
        assert_eq!(c[5], fixed(r, "rotations", 2), "{line}");
        assert_eq!(c[6], fixed(r, "cost", 3), "{line}");
        let repeated = 100.0 * f(r, "repeated_bearing_fraction");
        assert_eq!(c[7], format!("{repeated:.0} %"), "{line}");
        checked += 1;
    }
    assert_eq!(checked, 10, "the greedy table has 10 rows");
}

#[test]
fn the_greedy_confident_table_is_results_greedy_confident() {
    let readme = read(RESULTS);
    let results = json("results/greedy-confident/results.json");
    let at = readme
        .find("### Greedy agents with the calibrated stop")
        .unwrap();
    let rows: Vec<Vec<String>> = table_at(&readme[at..], "", "| K |");
    assert_eq!(rows.len(), 2, "a K = 1 and a K = 10 row");
    for c in rows {
        let k: u64 = c[0].parse().unwrap();
        for (agent, cell) in ["oigm", "oigm-cost", "eem", "heuristic-1"]
            .iter()
            .zip(&c[1..])
        {
            let r = row(&results, agent, k);
            let want = format!(
                "{} / {} / {} / {} of {}",
                fixed(r, "right", 3),
                fixed(r, "measurements", 2),
                fixed(r, "cost", 3),
                f(r, "wrong"),
                f(r, "answered")
            );
            assert_eq!(cell, &want, "greedy-confident, {agent} K = {k}");
        }
    }
}

#[test]
fn the_ablation_table_is_results_ablations() {
    let readme = read(RESULTS);
    let main = json("results/results.json");
    let mut checked = 0;
    let section = "## Ablations (paper §4.4)";
    let at = readme.find(section).unwrap();
    let rows: Vec<Vec<String>> = table_at(&readme[at..], "", "| policy |");
    for c in rows {
        let k: u64 = c[1].parse().unwrap();
        if c[0] == "full, A2C seed 1" {
            // K = 10's committed policy is PPO's; the ablations are the A2C command plus one
            // switch, so their full row is the A2C command's seed 1, from its seeds report.
            let md = read(&format!("policies/ablations/k{k}-full-a2c/seeds.md"));
            let seed1 = md
                .lines()
                .find(|l| l.starts_with("| 1 |"))
                .map(cells)
                .expect("the A2C seeds report has a seed-1 row");
            // seed | val. recognition | val. cost | recognition | cost | measurements | rotations | pose error | …
            let want = [&seed1[3], &seed1[7], &seed1[5], &seed1[6], &seed1[4]];
            let got = [&c[2], &c[3], &c[4], &c[5], &c[6]];
            assert_eq!(got, want, "{}", c.join(" | "));
            checked += 1;
            continue;
        }
        let dir = match c[0].as_str() {
            "full (committed)" => None,
            "without the registration-error reward" => Some("no-registration-reward"),
            "without topological scans" => Some("no-scans"),
            "without the belief map (scans + history)" => Some("no-belief"),
            other => panic!("unknown ablation row {other}"),
        };
        let results = match dir {
            None => main.clone(),
            Some(d) => json(&format!("results/ablations/k{k}-{d}/results.json")),
        };
        let r = row(&results, "learnt", k);
        let line = c.join(" | ");
        assert_eq!(c[2], fixed(r, "recognition_rate", 3), "{line}");
        assert_eq!(c[3], fixed(r, "pose_error", 4), "{line}");
        assert_eq!(c[4], fixed(r, "measurements", 2), "{line}");
        assert_eq!(c[5], fixed(r, "rotations", 2), "{line}");
        assert_eq!(c[6], fixed(r, "cost", 3), "{line}");
        checked += 1;
    }
    assert_eq!(checked, 8, "the ablation table has 8 rows");
}

/// The three-seed ablation tables are the `ablation_seeds` example's output, row for row.
#[test]
fn the_ablation_seed_tables_are_results_ablations_seeds() {
    let readme = read(RESULTS);
    let at = readme.find("## Ablations (paper §4.4)").unwrap();
    let section = &readme[at..];
    // The A2C study at both K, and the K = 10 ablations retrained with PPO's update.
    for table in ["k1", "k10", "k10-ppo"] {
        let md = read(&format!("results/ablations/seeds-{table}.md"));
        let rows: Vec<&str> = md
            .lines()
            .filter(|l| l.starts_with("| ") && !l.starts_with("| policy |"))
            .collect();
        assert_eq!(
            rows.len(),
            4,
            "full and three ablations in seeds-{table}.md"
        );
        for r in rows {
            assert!(
                section.contains(r),
                "{RESULTS} lacks, from seeds-{table}.md: {r}"
            );
        }
    }
}

#[test]
fn the_agreement_table_is_results_policy_agreement() {
    let readme = read(RESULTS);
    let runs = json("results/policy-agreement.json");
    let at = readme.find("## The int8 policy on the instrument").unwrap();
    let rows: Vec<Vec<String>> = table_at(&readme[at..], "", "| K |");
    assert_eq!(rows.len(), 2, "a K = 1 and a K = 10 row");
    for c in rows {
        let k: u64 = c[0].parse().unwrap();
        let a = &runs
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["agreement"]["rot_bins"] == k)
            .unwrap_or_else(|| panic!("no agreement run for K = {k}"))["agreement"];
        let states = f(a, "states") as u64;
        let thousands = format!("{},{:03}", states / 1000, states % 1000);
        let shown = if states >= 1000 {
            thousands
        } else {
            states.to_string()
        };
        let line = c.join(" | ");
        assert_eq!(c[1], shown, "{line}");
        assert_eq!(c[2], fixed(a, "action_agreement", 4), "{line}");
        assert_eq!(
            c[3],
            format!("{} / {}", f(a, "identical_episodes"), f(a, "plans")),
            "{line}"
        );
        assert_eq!(
            c[4],
            format!(
                "{} / {}",
                fixed(&a["float"], "success_rate", 3),
                fixed(&a["int8"], "success_rate", 3)
            ),
            "{line}"
        );
    }
}

#[test]
fn the_fig4_table_is_the_committed_aggregates() {
    // docs/results.md: | distance | K = 1 measure | K = 1 rotate | K = 10 measure | K = 10 rotate |,
    // from the "activation, measure / rotate" columns of docs/inspect/k{1,10}/aggregate.md.
    let readme = read(RESULTS);
    let at = readme.find("**Fig. 4 over 200 test plans**").unwrap();
    let rows: Vec<Vec<String>> = table_at(&readme[at..], "", "| distance from the visual centre");
    let aggregate = |k: u32| -> Vec<Vec<String>> {
        read(&format!("docs/inspect/k{k}/aggregate.md"))
            .lines()
            .skip_while(|l| !l.starts_with("| distance from the visual centre"))
            .skip(2)
            .take_while(|l| l.starts_with('|'))
            .map(cells)
            .collect()
    };
    let (k1, k10) = (aggregate(1), aggregate(10));
    assert_eq!(rows.len(), 6, "six distance bands in {RESULTS}");
    assert_eq!(
        (k1.len(), k10.len()),
        (6, 6),
        "six distance bands in each aggregate"
    );
    for (i, c) in rows.iter().enumerate() {
        let want = [&k1[i][2], &k1[i][3], &k10[i][2], &k10[i][3]];
        assert_eq!(
            c[1..5].iter().collect::<Vec<_>>(),
            want,
            "{RESULTS} Fig.-4 row {}",
            c[0]
        );
    }
}

/// The README is a user's guide: short, and free of the project's history (commit hashes and
/// issue numbers belong to the lab notebook, `docs/lab/`).
#[test]
fn the_readme_is_a_short_guide_without_history() {
    let readme = read("README.md");
    let lines = readme.lines().count();
    assert!(lines <= 250, "README.md has {lines} lines (at most 250)");
    for (n, line) in readme.lines().enumerate() {
        assert!(
            !line.contains("commit `"),
            "README.md:{}: names a commit: {line}",
            n + 1
        );
        let words: Vec<&str> = line.split_whitespace().collect();
        for w in words.windows(2) {
            let number = w[1].trim_start_matches('#');
            let number = number.trim_end_matches(|c: char| !c.is_ascii_digit());
            assert!(
                !(w[0].eq_ignore_ascii_case("issue")
                    && !number.is_empty()
                    && number.chars().all(|c| c.is_ascii_digit())),
                "README.md:{}: names an issue: {line}",
                n + 1
            );
        }
        // A bare commit id: 7 to 40 hex digits, with a digit and a letter among them.
        for token in line.split(|c: char| !c.is_ascii_alphanumeric()) {
            let hex = (7..=40).contains(&token.len())
                && token.chars().all(|c| c.is_ascii_hexdigit())
                && token.chars().any(|c| c.is_ascii_digit())
                && token.chars().any(|c| c.is_ascii_alphabetic());
            assert!(!hex, "README.md:{}: a commit id? {token}: {line}", n + 1);
        }
    }
}
