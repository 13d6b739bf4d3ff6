//! The command reference in `docs/cli/` against the binary's own `--help`: every flag
//! of every command is on its page, and no page (nor README.md) names a flag that no
//! command has.

use std::collections::BTreeSet;

use crate::util::{expect_code, run};

/// Each page and the command it documents.
const PAGES: &[(&str, &[&str])] = &[
    ("simulate.md", &["simulate"]),
    ("collect.md", &["collect"]),
    ("dataset-info.md", &["dataset", "info"]),
    ("dataset-merge.md", &["dataset", "merge"]),
    ("train-autoencoder.md", &["train", "autoencoder"]),
    ("train-world-model.md", &["train", "world-model"]),
    ("train-policy.md", &["train", "policy"]),
    ("train-judge.md", &["train", "judge"]),
    ("train-adapt.md", &["train", "adapt"]),
    ("read-judge.md", &["read-judge"]),
    ("wm-eval.md", &["wm", "eval"]),
    ("wm-export.md", &["wm", "export"]),
    ("scripted.md", &["scripted"]),
    ("export-policies.md", &["export-policies"]),
    ("rank.md", &["rank"]),
    ("merge.md", &["merge"]),
    ("report.md", &["report"]),
    ("agreement.md", &["agreement"]),
    ("tasks.md", &["tasks"]),
    ("plan.md", &["plan"]),
    ("import-world-model.md", &["import", "world-model"]),
    ("import-judge.md", &["import", "judge"]),
    ("import-policy.md", &["import", "policy"]),
];

/// Flags every command has, documented once in `docs/cli/README.md`.
const GLOBAL: &[&str] = &["--help", "--version", "--verbose", "--quiet", "--render-workers"];

/// Flags of cargo and of the project's scripts, which README.md names too.
const TOOLS: &[&str] =
    &["--release", "--features", "--all", "--all-targets", "--bench", "--workspace", "--no-build"];

/// Every `--flag` in `text` (a flag: `--`, then a lowercase letter, then letters,
/// digits and single dashes, not preceded by a letter, digit or dash).
fn flags(text: &str) -> BTreeSet<String> {
    let b = text.as_bytes();
    let mut out = BTreeSet::new();
    let mut i = 0;
    while i + 2 < b.len() {
        let before_ok = i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'-');
        if before_ok && b[i] == b'-' && b[i + 1] == b'-' && b[i + 2].is_ascii_lowercase() {
            let mut j = i + 2;
            while j < b.len() && (b[j].is_ascii_lowercase() || b[j].is_ascii_digit() || b[j] == b'-') {
                j += 1;
            }
            out.insert(text[i..j].trim_end_matches('-').to_string());
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

/// The flags `evalharness <command> --help` lists.
fn help_flags(command: &[&str]) -> BTreeSet<String> {
    let (stdout, _) = expect_code(&run(&[command, &["--help"]].concat()), 0);
    // Only the option lines' own names: a description may mention other flags.
    let names: String = stdout
        .lines()
        .filter_map(|l| {
            let l = l.trim_start();
            let l = l
                .strip_prefix("-")
                .filter(|r| r.chars().next().is_some_and(|c| c != '-'))
                .map_or(l, |r| r.split_once(", ").map_or(l, |(_, rest)| rest));
            l.starts_with("--").then(|| l.split_whitespace().next().unwrap_or("").to_string())
        })
        .collect::<Vec<_>>()
        .join(" ");
    flags(&names)
}

#[test]
fn every_flag_is_documented_and_every_documented_flag_exists() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut known: BTreeSet<String> = GLOBAL.iter().chain(TOOLS).map(|s| (*s).to_string()).collect();
    let mut problems = Vec::new();
    for (page, command) in PAGES {
        let text = std::fs::read_to_string(root.join("docs/cli").join(page)).expect(page);
        let have = help_flags(command);
        let documented = flags(&text);
        for f in have.iter().filter(|f| !GLOBAL.contains(&f.as_str())) {
            if !documented.contains(f) {
                problems.push(format!(
                    "docs/cli/{page}: `evalharness {}` has {f}, the page does not name it",
                    command.join(" ")
                ));
            }
        }
        known.extend(have);
    }
    // Every page, the index and README.md may name only flags some command has.
    let mut texts: Vec<(String, String)> = PAGES
        .iter()
        .map(|(p, _)| {
            (format!("docs/cli/{p}"), std::fs::read_to_string(root.join("docs/cli").join(p)).unwrap())
        })
        .collect();
    for extra in ["docs/cli/README.md", "README.md"] {
        texts.push((extra.to_string(), std::fs::read_to_string(root.join(extra)).expect(extra)));
    }
    for (name, text) in &texts {
        for f in flags(text).difference(&known) {
            problems.push(format!("{name} names {f}, which no command has"));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn flags_are_read_from_prose_and_help_alike() {
    let f = flags("use `--max-steps 300` or --jobs, not x--y nor ---z; `-q`/`--quiet`.");
    assert_eq!(f.into_iter().collect::<Vec<_>>(), ["--jobs", "--max-steps", "--quiet"]);
}
