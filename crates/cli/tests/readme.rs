//! The guide's CLI chapters run as printed: each ```console block of the README's "A short
//! tour" and of the user guide's device chapters (docs/guide/src: "JBC hot-air station",
//! "Thermosald ISC", "Modbus RTU / JBUS and the Chloride CROSS", "Modbus TCP, typed values,
//! scanning", "Panasonic BM") is read from its file at test time and played the way a reader
//! would type it.
//!
//! - `$ cellbus sim … &` starts the simulator; the lines under it are what it prints first
//!   (`listening on tcp://127.0.0.1:33331`). The address it really got (port 0 picks one)
//!   replaces the text's in every later command and output line of the block.
//! - `$ cellbus sim …` without `&` runs a simulator in the foreground with its control
//!   channel: a line followed by an `ok: …` or `error: …` line is typed into it, the other
//!   is its answer; the lines before the first typed one are what it prints first.
//! - Any other `$ …` line runs through `sh` from the workspace's root, with this build's
//!   `cellbus` first on PATH (pipes to `head` work), stdout and stderr together as a
//!   terminal shows them; the lines under it are its whole output.
//!
//! Output lines must match exactly (trailing blanks aside), except where the text says
//! that numbers vary: an HTML comment right above the block, e.g.
//! `<!-- vary: AT1 | ET1 | # s -->`, lists how such lines start (`#` stands for any number;
//! runs of blanks count as one). In an output line that starts so, numbers may differ from
//! the text's; its words, units and their order may not, nor its count of numbers. A
//! pattern that matches no line of its block fails the test, so none outlives its line.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// How long one command may run: the longest waits for a placement machine's first board
/// (22 s); a passing run ends long before.
const LIMIT: Duration = Duration::from_secs(180);

#[test]
fn the_readme_tour_runs_as_printed() {
    run_section("README.md", "## A short tour");
}

#[test]
fn the_jbc_chapter_runs_as_printed() {
    run_section("docs/guide/src/jbc.md", "# JBC hot-air station");
}

#[test]
fn the_thermosald_chapter_runs_as_printed() {
    run_section("docs/guide/src/thermosald.md", "# Thermosald ISC");
}

#[test]
fn the_modbus_and_cross_chapter_runs_as_printed() {
    run_section(
        "docs/guide/src/modbus.md",
        "# Modbus RTU / JBUS and the Chloride CROSS",
    );
}

#[test]
fn the_modbus_tcp_chapter_runs_as_printed() {
    run_section(
        "docs/guide/src/modbus-tcp.md",
        "# Modbus TCP, typed values, scanning",
    );
}

#[test]
fn the_panasonic_chapter_runs_as_printed() {
    run_section("docs/guide/src/panasonic.md", "# Panasonic BM");
}

#[test]
fn a_section_ends_at_a_heading_of_its_level_outside_code() {
    let text = "# A\nintro\n## B\nb\n```sh\n# a comment\n```\n### C\nc\n## D\nd\n# E\n";
    assert_eq!(
        section(text, "## B"),
        ["b", "```sh", "# a comment", "```", "### C", "c"]
    );
    assert_eq!(section(text, "# A").len(), 10);
    assert_eq!(heading_level("#hashtag"), None);
}

#[test]
fn numbers_may_vary_only_in_lines_the_text_marks() {
    let marked = Block::parse_vary("<!-- vary: AT1 | # s -->").expect("a vary comment");
    let block = Block {
        vary: marked,
        lines: Vec::new(),
    };
    assert!(block.varies("AT1 air temperature (tool thermocouple)           76 °C"));
    assert!(block.varies("3.0 s                215 °C          35 °C   1000 ‰  tool on"));
    assert!(!block.varies("ST1 selected air temperature                      380 °C"));
    assert!(!block.varies("0x12 s"), "0x12 is not a number here");
    assert!(same_but_numbers(
        "1.0 s   135 °C   28 °C",
        "1.1 s    99 °C   28 °C"
    ));
    assert!(!same_but_numbers("1.0 s 135 °C", "1.0 s 135 %"));
    assert!(!same_but_numbers("1.0 s 135 °C", "1.0 s 135 1 °C"));
}

/// The workspace's root, where the README and the guide are and the commands run.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Runs every console block of the section under `heading` (its subsections included) in
/// `file`, a path from the workspace's root.
fn run_section(file: &str, heading: &str) {
    let text = std::fs::read_to_string(root().join(file))
        .unwrap_or_else(|e| panic!("cannot read {file}: {e}"));
    let blocks = Block::all_in(&section(&text, heading));
    assert!(
        !blocks.is_empty(),
        "no ```console block under {heading} in {file}"
    );
    for block in &blocks {
        block.run();
    }
}

/// The lines under `heading` (`## A short tour`, `# Panasonic BM`) up to the next heading
/// of its level or above; a `#` line inside a code block is not a heading.
fn section<'a>(text: &'a str, heading: &str) -> Vec<&'a str> {
    let level = heading_level(heading).expect("a Markdown heading");
    let mut lines = text.lines().skip_while(|line| *line != heading);
    assert!(lines.next().is_some(), "no heading {heading:?}");
    let mut fenced = false;
    lines
        .take_while(|line| {
            if line.starts_with("```") {
                fenced = !fenced;
            }
            fenced || heading_level(line).is_none_or(|l| l > level)
        })
        .collect()
}

/// 2 for `## Title`; none for a line that is not a heading.
fn heading_level(line: &str) -> Option<usize> {
    let hashes = line.len() - line.trim_start_matches('#').len();
    (hashes > 0 && line[hashes..].starts_with(' ')).then_some(hashes)
}

/// One ```console block and the `vary` patterns written above it.
struct Block {
    vary: Vec<String>,
    lines: Vec<String>,
}

impl Block {
    /// The console blocks among `lines`.
    fn all_in(lines: &[&str]) -> Vec<Block> {
        let mut lines = lines.iter().copied();
        let mut blocks = Vec::new();
        let mut vary = Vec::new();
        while let Some(line) = lines.next() {
            if let Some(patterns) = Block::parse_vary(line) {
                vary = patterns;
            } else if line == "```console" {
                let body = lines
                    .by_ref()
                    .take_while(|line| *line != "```")
                    .map(str::to_owned)
                    .collect();
                blocks.push(Block {
                    vary: std::mem::take(&mut vary),
                    lines: body,
                });
            } else {
                vary.clear();
            }
        }
        blocks
    }

    /// The patterns of a `<!-- vary: A | B -->` line.
    fn parse_vary(line: &str) -> Option<Vec<String>> {
        let inner = line.strip_prefix("<!-- vary:")?.strip_suffix("-->")?;
        Some(inner.split('|').map(|p| shape(p.trim())).collect())
    }

    /// Whether numbers may vary in the text's output line `line`.
    fn varies(&self, line: &str) -> bool {
        let line = shape(line);
        self.vary
            .iter()
            .any(|pattern| line.starts_with(pattern.as_str()))
    }

    /// Plays the block: its commands, each output checked against the text's lines.
    fn run(&self) {
        let mut play = Play {
            block: self,
            addresses: Vec::new(),
            sims: Vec::new(),
            used: vec![false; self.vary.len()],
        };
        let mut steps = self.lines.iter().peekable();
        while let Some(line) = steps.next() {
            let command = line
                .strip_prefix("$ ")
                .unwrap_or_else(|| panic!("a block goes on with a `$ ` command, not {line:?}"));
            let mut expected = Vec::new();
            while let Some(next) = steps.next_if(|l| !l.starts_with("$ ")) {
                expected.push(next.clone());
            }
            play.step(command, &expected);
        }
        for (pattern, used) in self.vary.iter().zip(&play.used) {
            assert!(
                used,
                "vary pattern {pattern:?} matches no line of its block"
            );
        }
    }
}

/// A block being played: the addresses learnt so far and the simulators it started.
struct Play<'a> {
    block: &'a Block,
    /// The text's address → the running simulator's.
    addresses: Vec<(String, String)>,
    /// Killed when the block ends, as the reader's shell would end them.
    sims: Vec<Sim>,
    /// Which vary patterns matched a line.
    used: Vec<bool>,
}

impl Play<'_> {
    fn step(&mut self, command: &str, expected: &[String]) {
        let command = self.substituted(command);
        if let Some(sim) = command.strip_prefix("cellbus sim ") {
            match sim.strip_suffix(" &") {
                Some(args) => self.background(args, expected),
                None => self.foreground(sim, expected),
            }
            return;
        }
        let output = shell(&command);
        let expected: Vec<String> = expected.iter().map(|l| self.substituted(l)).collect();
        let got: Vec<&str> = output.lines().collect();
        let context = || {
            format!(
                "$ {command}\n--- expected:\n{}\n--- got:\n{output}",
                expected.join("\n")
            )
        };
        assert_eq!(got.len(), expected.len(), "{}", context());
        for (want, got) in expected.iter().zip(&got) {
            self.check(want, got, &context);
        }
    }

    /// `cellbus sim ARGS &`: started, its first lines compared, its addresses learnt.
    fn background(&mut self, args: &str, expected: &[String]) {
        let mut sim = Sim::spawn(args, Stdio::null());
        for want in expected {
            let got = sim.line();
            self.learn(want, &got);
        }
        self.sims.push(sim);
    }

    /// `cellbus sim ARGS` with typed commands, each answered by one line.
    fn foreground(&mut self, args: &str, expected: &[String]) {
        let mut sim = Sim::spawn(args, Stdio::piped());
        let mut stdin = sim.child.stdin.take().expect("stdin is piped");
        let answers = |line: Option<&String>| {
            line.is_some_and(|l| l.starts_with("ok: ") || l.starts_with("error: "))
        };
        let mut lines = expected.iter().peekable();
        while let Some(line) = lines.next() {
            if answers(lines.peek().copied()) {
                writeln!(stdin, "{line}").expect("the simulator reads its stdin");
                let answer = lines.next().expect("peeked");
                let got = sim.line();
                self.check(answer, &got, &|| {
                    format!("typed {line:?} into cellbus sim {args}")
                });
            } else {
                let got = sim.line();
                self.learn(line, &got);
            }
        }
        self.sims.push(sim);
    }

    /// A simulator's first line: the text's (`listening on tcp://127.0.0.1:33331`) with
    /// another address; other lines must match.
    fn learn(&mut self, want: &str, got: &str) {
        match (address_in(want), address_in(got)) {
            (Some((want_head, written)), Some((got_head, real))) => {
                assert_eq!(
                    want_head, got_head,
                    "a simulator printed {got:?}, not {want:?}"
                );
                self.addresses.push((written.to_owned(), real.to_owned()));
                // `--events-port 41715` names the port alone.
                if let (Some((_, written)), Some((_, real))) =
                    (written.rsplit_once(':'), real.rsplit_once(':'))
                {
                    self.addresses.push((written.to_owned(), real.to_owned()));
                }
            }
            _ => self.check(want, got, &|| "a simulator's first lines".to_owned()),
        }
    }

    fn check(&mut self, want: &str, got: &str, context: &dyn Fn() -> String) {
        let (want, got) = (want.trim_end(), got.trim_end());
        let varies: Vec<usize> = (0..self.block.vary.len())
            .filter(|&i| shape(want).starts_with(self.block.vary[i].as_str()))
            .collect();
        for &i in &varies {
            self.used[i] = true;
        }
        if varies.is_empty() {
            assert_eq!(got, want, "{}", context());
        } else {
            assert!(
                same_but_numbers(want, got),
                "{got:?} differs from {want:?} in more than its numbers\n{}",
                context()
            );
        }
    }

    /// `text` with the addresses it was written with replaced by the simulators'.
    fn substituted(&self, text: &str) -> String {
        let words: Vec<String> = text
            .split(' ')
            .map(|word| {
                let found = self.addresses.iter().find_map(|(written, real)| {
                    let at = word.find(written.as_str())?;
                    // A port alone is one only as a whole word: 41715, not 1417150.
                    (written.contains(':') || word == written)
                        .then(|| format!("{}{real}{}", &word[..at], &word[at + written.len()..]))
                });
                found.unwrap_or_else(|| word.to_owned())
            })
            .collect();
        words.join(" ")
    }
}

/// A simulator a block starts, killed when dropped.
struct Sim {
    child: Child,
    stdout: BufReader<ChildStdout>,
}

impl Sim {
    fn spawn(args: &str, stdin: Stdio) -> Sim {
        let mut child = sh(&format!("exec cellbus sim {args}"))
            .stdin(stdin)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("sh runs");
        let stdout = BufReader::new(child.stdout.take().expect("stdout is piped"));
        Sim { child, stdout }
    }

    /// The next line it prints, without its end (empty once it has ended).
    fn line(&mut self) -> String {
        let mut line = String::new();
        self.stdout
            .read_line(&mut line)
            .expect("the simulator's stdout");
        line.trim_end_matches('\n').to_owned()
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `sh -c SCRIPT` from the workspace's root with this build's `cellbus` first on PATH and
/// no RUST_LOG (its logs would join the output).
fn sh(script: &str) -> Command {
    let bin = Path::new(env!("CARGO_BIN_EXE_cellbus"))
        .parent()
        .expect("the binary is in a directory");
    let path = std::env::var_os("PATH").unwrap_or_default();
    let path =
        std::env::join_paths(std::iter::once(bin.to_owned()).chain(std::env::split_paths(&path)))
            .expect("a PATH");
    let mut command = Command::new("sh");
    command
        .args(["-c", script])
        .current_dir(root())
        .env("PATH", path)
        .env_remove("RUST_LOG");
    command
}

/// Runs `line` as a reader's shell would, stdout and stderr together; its output.
fn shell(line: &str) -> String {
    let child = sh(&format!("exec 2>&1; {line}"))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .expect("sh runs");
    let id = child.id();
    let (done, finished) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = done.send(child.wait_with_output());
    });
    match finished.recv_timeout(LIMIT) {
        Ok(output) => String::from_utf8_lossy(&output.expect("sh ran").stdout).into_owned(),
        Err(_) => {
            let _ = Command::new("kill").arg(id.to_string()).status();
            panic!("$ {line} still running after {LIMIT:?}");
        }
    }
}

/// `listening on tcp://127.0.0.1:33331` → (`listening on tcp://`, `127.0.0.1:33331`).
fn address_in(line: &str) -> Option<(&str, &str)> {
    let start = line.find("://")? + 3;
    Some(line.split_at(start))
}

/// `line` with runs of blanks as one and each number as `#`. A number starts where a
/// word does not (the 1 of `ST1` is part of a word): `0.0 s  80 °C` is `# s # °C`.
fn shape(line: &str) -> String {
    let mut shaped = String::new();
    let mut chars = line.trim().chars().peekable();
    let mut previous = ' ';
    while let Some(c) = chars.next() {
        if c.is_whitespace() {
            while chars.next_if(|c| c.is_whitespace()).is_some() {}
            shaped.push(' ');
            previous = ' ';
            continue;
        }
        let starts_number =
            c.is_ascii_digit() || (c == '-' && chars.peek().is_some_and(char::is_ascii_digit));
        if starts_number && !previous.is_alphanumeric() {
            while chars.next_if(|c| c.is_ascii_digit() || *c == '.').is_some() {}
            shaped.push('#');
            previous = '#';
        } else {
            shaped.push(c);
            previous = c;
        }
    }
    shaped
}

/// Whether two lines differ at most in their numbers (and runs of blanks).
fn same_but_numbers(a: &str, b: &str) -> bool {
    shape(a) == shape(b)
}
