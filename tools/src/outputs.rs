//! Every file a command writes goes through here (issue 24 items 10, 13, 14), so that
//!
//! * **every output path is checked before the work** ([`OutFile::check`], [`OutDir::check`],
//!   [`Outputs::check`]): a file's folder exists and takes a file, a path is not a folder; a
//!   report folder is a folder (or can be made under the nearest folder that exists) and
//!   takes files. The check writes (and removes) a probe file, so it answers exactly what
//!   the write will meet (permissions, read-only mounts, a file where a folder should be);
//! * **no output is ever half-written**: each file is written to a temporary file in its own
//!   folder and renamed over the target when complete ([`write_atomic`]); a failure leaves
//!   the target as it was (absent, or its earlier content) and no temporary file;
//! * **nothing is written outside the output folder**: a file in a folder is named by
//!   [`OutDir::file`], which takes plain file names only ([`safe_file_name`]: no folder, no
//!   `..`);
//! * **`-` is standard output** for single-file outputs where it makes sense (`--json -`,
//!   `decode -o -`); then the lines a command prints for people ([`say!`]) go to standard
//!   error, so standard output holds the file alone.
//!
//! `--json FILE` and `--report DIR` are one flag definition ([`Outputs`]) shared by the
//! commands that have them.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use serde::Serialize;

/// The path that means standard output.
pub const STDOUT: &str = "-";

/// Whether an output (`-`) writes to standard output: then [`say!`] prints to standard
/// error.
static STDOUT_TAKEN: AtomicBool = AtomicBool::new(false);

/// Prints a line for people: on standard output, or on standard error when an output
/// (`--json -`, `decode -o -`) has standard output.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::outputs::say_line(format_args!($($arg)*))
    };
}

/// The line of [`say!`].
pub fn say_line(args: std::fmt::Arguments) {
    if STDOUT_TAKEN.load(Ordering::Relaxed) {
        eprintln!("{args}");
    } else {
        println!("{args}");
    }
}

/// Whether standard output is taken by an output file (`-`).
pub fn stdout_taken() -> bool {
    STDOUT_TAKEN.load(Ordering::Relaxed)
}

/// A plain file name (what a run name must be to name files): 1-100 characters of
/// letters, digits, `-`, `_` and `.`, not starting with `.` (no folder separator, no `..`,
/// no hidden file). The error says why.
pub fn safe_file_name(name: &str) -> std::result::Result<(), String> {
    if name.is_empty() {
        return Err("is empty".into());
    }
    if name.chars().count() > 100 {
        return Err("is longer than 100 characters".into());
    }
    if name.starts_with('.') {
        return Err("starts with `.` (a hidden file, or `..`, a folder above)".into());
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.')))
    {
        let what = if matches!(c, '/' | '\\') {
            "a folder separator".to_string()
        } else {
            format!("`{}`", c.escape_default())
        };
        return Err(format!(
            "contains {what}: it names files, so only letters, digits, `-`, `_` and `.` are allowed"
        ));
    }
    Ok(())
}

/// The folder a file path is in (`.` for a bare name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Whether a file can be created in the existing folder `dir`: a probe file is created
/// and removed (the exact answer: permissions, read-only mounts, quota).
fn probe_folder(dir: &Path, what: &str, target: &Path) -> Result<()> {
    tempfile::Builder::new()
        .prefix(".hils-probe-")
        .tempfile_in(dir)
        .map(drop)
        .map_err(|e| {
            anyhow!(
                "{what} {}: cannot write into {}: {e}",
                target.display(),
                dir.display()
            )
        })
}

/// Writes a file atomically: `write` fills a temporary file in the target's folder, which
/// is renamed over `path` once complete. On any error the target is left as it was and the
/// temporary file is removed.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let dir = folder_of(path);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".part");
    // As a plain create would make it (0666 less the umask), not tempfile's private 0600.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let tmp = builder
        .tempfile_in(dir)
        .with_context(|| format!("cannot write {}", path.display()))?;
    let mut out = std::io::BufWriter::with_capacity(1 << 16, tmp);
    write(&mut out).with_context(|| format!("cannot write {}", path.display()))?;
    let tmp = out
        .into_inner()
        .map_err(|e| anyhow!("cannot write {}: {}", path.display(), e.error()))?;
    tmp.persist(path)
        .map_err(|e| anyhow!("cannot write {}: {}", path.display(), e.error))?;
    Ok(())
}

/// Writes `bytes` to `path` atomically ([`write_atomic`]).
pub fn write_file(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    write_atomic(path, |w| Ok(w.write_all(bytes.as_ref())?))
}

/// Pretty JSON with a final newline.
fn json_text(value: &impl Serialize) -> Result<String> {
    Ok(serde_json::to_string_pretty(value)? + "\n")
}

/// A single-file output, checked: standard output (`-`) or a file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum OutFile {
    Stdout,
    File(PathBuf),
}

impl OutFile {
    /// Checks the output `path` of `what` (`--json`, `-o`, ...) before any work: `-` is
    /// standard output (one output only may take it); a file must not be a folder and its
    /// folder must exist and take files.
    pub fn check(path: &Path, what: &str) -> Result<OutFile> {
        if path.as_os_str() == STDOUT {
            if STDOUT_TAKEN.swap(true, Ordering::Relaxed) {
                bail!("{what} -: standard output is already taken by another output");
            }
            return Ok(OutFile::Stdout);
        }
        if path.is_dir() {
            bail!("{what} {}: is a folder, not a file", path.display());
        }
        let dir = folder_of(path);
        if !dir.is_dir() {
            bail!(
                "{what} {}: the folder {} does not exist (or is not a folder)",
                path.display(),
                dir.display()
            );
        }
        probe_folder(dir, what, path)?;
        Ok(OutFile::File(path.to_path_buf()))
    }

    /// Refuses an output file that is one of the command's inputs (`inputs`: the flag or
    /// argument that names it, its path): the output, written once the work is done, would
    /// replace the input (`--json` naming the programme or the log).
    pub fn not_over(self, what: &str, inputs: &[(&str, &Path)]) -> Result<OutFile> {
        if let OutFile::File(out) = &self {
            for (flag, input) in inputs {
                if same_file(out, input) {
                    bail!(
                        "{what} {}: is the {flag} input {}: writing it would replace the input; name another file",
                        out.display(),
                        input.display()
                    );
                }
            }
        }
        Ok(self)
    }

    /// Checks a file output that cannot be standard output (`what -` is refused with why).
    pub fn check_file(path: &Path, what: &str, why_not_stdout: &str) -> Result<OutFile> {
        if path.as_os_str() == STDOUT {
            bail!("{what} -: {why_not_stdout}");
        }
        Self::check(path, what)
    }

    /// Writes the output: a file atomically, standard output as it comes.
    pub fn write_with(&self, write: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
        match self {
            OutFile::File(p) => write_atomic(p, write),
            OutFile::Stdout => {
                let mut out = std::io::stdout().lock();
                write(&mut out)?;
                out.flush()?;
                Ok(())
            }
        }
    }

    /// Writes `bytes`.
    pub fn write(&self, bytes: impl AsRef<[u8]>) -> Result<()> {
        self.write_with(|w| Ok(w.write_all(bytes.as_ref())?))
    }

    /// Writes `value` as pretty JSON.
    pub fn write_json(&self, value: &impl Serialize) -> Result<()> {
        self.write(json_text(value)?)
    }

    /// The file's path (None for standard output).
    pub fn path(&self) -> Option<&Path> {
        match self {
            OutFile::File(p) => Some(p),
            OutFile::Stdout => None,
        }
    }

    /// The output for messages: its path, or `standard output`.
    pub fn describe(&self) -> String {
        match self {
            OutFile::File(p) => p.display().to_string(),
            OutFile::Stdout => "standard output".into(),
        }
    }
}

/// Whether two paths name one existing file (links and `..` resolved).
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// An output folder, checked: its files are named by [`OutDir::file`] (plain names only),
/// written atomically, and the folder is made when the first file is written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OutDir {
    dir: PathBuf,
}

impl OutDir {
    /// Checks the output folder `path` of `what` (`--report`, `--out`) before any work: an
    /// existing folder that takes files, or a path under the nearest existing folder that
    /// takes files (nothing on the way is a file).
    pub fn check(path: &Path, what: &str) -> Result<OutDir> {
        if path.as_os_str() == STDOUT {
            bail!("{what} -: a folder of files cannot go to standard output");
        }
        let mut existing = path;
        while !existing.exists() {
            existing = match existing.parent() {
                Some(p) if !p.as_os_str().is_empty() => p,
                _ => Path::new("."),
            };
        }
        if !existing.is_dir() {
            bail!(
                "{what} {}: {} is a file, not a folder",
                path.display(),
                existing.display()
            );
        }
        probe_folder(existing, what, path)?;
        Ok(OutDir {
            dir: path.to_path_buf(),
        })
    }

    /// Whether `path` is the folder's file `name` (an output the folder will hold: `--json`
    /// naming a run's log in `--report DIR` would replace it).
    pub fn holds(&self, path: &Path, name: &str) -> bool {
        let dir = std::fs::canonicalize(&self.dir);
        let parent = std::fs::canonicalize(folder_of(path));
        matches!((dir, parent), (Ok(d), Ok(p)) if d == p)
            && path.file_name().is_some_and(|n| n == name)
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// Makes the folder (and those above it) if needed.
    pub fn create(&self) -> Result<()> {
        std::fs::create_dir_all(&self.dir)
            .with_context(|| format!("cannot create {}", self.dir.display()))
    }

    /// The path of file `name` in the folder; `name` must be a plain file name
    /// ([`safe_file_name`]): nothing is written outside the folder.
    pub fn file(&self, name: &str) -> Result<PathBuf> {
        safe_file_name(name).map_err(|why| {
            anyhow!(
                "file name `{name}` in {}: {why}; nothing is written outside the output folder",
                self.dir.display()
            )
        })?;
        Ok(self.dir.join(name))
    }

    /// Writes file `name` of the folder atomically with `write`; returns its path.
    pub fn write_with(
        &self,
        name: &str,
        write: impl FnOnce(&mut dyn Write) -> Result<()>,
    ) -> Result<PathBuf> {
        let path = self.file(name)?;
        self.create()?;
        write_atomic(&path, write)?;
        Ok(path)
    }

    /// Writes `bytes` as file `name` of the folder; returns its path.
    pub fn write(&self, name: &str, bytes: impl AsRef<[u8]>) -> Result<PathBuf> {
        self.write_with(name, |w| Ok(w.write_all(bytes.as_ref())?))
    }

    /// Writes `value` as pretty JSON to file `name`; returns its path.
    pub fn write_json(&self, name: &str, value: &impl Serialize) -> Result<PathBuf> {
        self.write(name, json_text(value)?)
    }
}

/// `--json FILE` and `--report DIR` of a subcommand (its help says what each holds).
#[derive(Args, Debug, Clone, Default)]
pub struct Outputs {
    /// Write the results as JSON to this file (`-`: standard output; the subcommand's
    /// format: see its docs).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write a report (report.md with SVG plots) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// The outputs of a command, checked before its work ([`Outputs::check`]).
#[derive(Clone, Debug, Default)]
pub struct Checked {
    pub json: Option<OutFile>,
    pub report: Option<OutDir>,
}

impl Outputs {
    /// Checks both outputs before the work (a command calls this first: nothing is written
    /// unless both can be).
    pub fn check(&self) -> Result<Checked> {
        Ok(Checked {
            json: self
                .json
                .as_deref()
                .map(|p| OutFile::check(p, "--json"))
                .transpose()?,
            report: self
                .report
                .as_deref()
                .map(|p| OutDir::check(p, "--report"))
                .transpose()?,
        })
    }
}

impl Checked {
    /// Refuses a `--json` file that is one of the command's inputs ([`OutFile::not_over`]).
    pub fn not_over(mut self, inputs: &[(&str, &Path)]) -> Result<Checked> {
        self.json = self
            .json
            .map(|j| j.not_over("--json", inputs))
            .transpose()?;
        Ok(self)
    }

    /// Writes `value` to the `--json` output, if one was given, and names it.
    pub fn write_json(&self, value: &impl Serialize) -> Result<()> {
        if let Some(out) = &self.json {
            out.write_json(value)?;
            if let OutFile::File(p) = out {
                crate::say!("wrote {}", p.display());
            }
        }
        Ok(())
    }

    /// Calls `write` with the `--report` folder (made), if one was given, and names the
    /// files it wrote.
    pub fn write_report(&self, write: impl FnOnce(&OutDir) -> Result<Vec<PathBuf>>) -> Result<()> {
        if let Some(dir) = &self.report {
            dir.create()?;
            for f in write(dir)? {
                crate::say!("wrote {}", f.display());
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hils-outputs-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn an_output_that_is_an_input_is_refused() {
        let dir = temp("over");
        let input = dir.join("programme.toml");
        std::fs::write(&input, "[[run]]").unwrap();
        let same = dir.join(".").join("programme.toml");
        let e = OutFile::check(&same, "--json")
            .unwrap()
            .not_over("--json", &[("--programme", &input)])
            .unwrap_err();
        assert!(format!("{e:#}").contains("--programme input"), "{e:#}");
        let report = OutDir::check(&dir, "--report").unwrap();
        assert!(report.holds(
            &dir.join("..").join(dir.file_name().unwrap()).join("a.csv"),
            "a.csv"
        ));
        assert!(!report.holds(&dir.join("b.csv"), "a.csv"));
        let other = OutFile::check(&dir.join("out.json"), "--json").unwrap();
        assert!(other.not_over("--json", &[("--programme", &input)]).is_ok());
        assert_eq!(std::fs::read_to_string(&input).unwrap(), "[[run]]");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_write_leaves_the_target_as_it_was_and_no_temporary_file() {
        let dir = temp("atomic");
        let path = dir.join("out.json");
        std::fs::write(&path, "old").unwrap();
        let e = write_atomic(&path, |w| {
            w.write_all(b"half of the new con")?;
            bail!("the work failed half-way")
        })
        .unwrap_err();
        assert!(format!("{e:#}").contains("half-way"), "{e:#}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(entries(&dir), ["out.json"]);
        write_file(&path, "new").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        assert_eq!(entries(&dir), ["out.json"]);
        // Readable by others as a plain create makes it (umask aside), not private.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_ne!(mode & 0o044, 0, "mode {mode:o}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn paths_are_checked_before_any_work() {
        let dir = temp("check");
        let file = dir.join("a-file");
        std::fs::write(&file, "x").unwrap();
        // A file where a folder should be, on either kind of output.
        let e = OutFile::check(&file.join("out.json"), "--json").unwrap_err();
        assert!(e.to_string().contains("--json"), "{e}");
        let e = OutDir::check(&file.join("report"), "--report").unwrap_err();
        assert!(e.to_string().contains("is a file, not a folder"), "{e}");
        // A folder as a file output; a missing folder of a file output.
        let e = OutFile::check(&dir, "-o").unwrap_err();
        assert!(e.to_string().contains("is a folder"), "{e}");
        let e = OutFile::check(&dir.join("no/such/x.csv"), "-o").unwrap_err();
        assert!(e.to_string().contains("does not exist"), "{e}");
        // A report folder not made yet under a folder that takes files: fine, not made yet.
        let report = OutDir::check(&dir.join("new/report"), "--report").unwrap();
        assert!(!dir.join("new").exists());
        report.write("report.md", "# r\n").unwrap();
        assert!(dir.join("new/report/report.md").is_file());
        // The probe leaves nothing behind.
        assert_eq!(entries(&dir), ["a-file", "new"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn nothing_is_written_outside_the_folder() {
        let dir = temp("names");
        let out = OutDir::check(&dir.join("report"), "--report").unwrap();
        for name in ["../../escape", "eb/120", "..", ".hidden", "", "a\\b", "x y"] {
            assert!(out.write(name, "x").is_err(), "{name:?} accepted");
            assert!(safe_file_name(name).is_err(), "{name:?}");
        }
        for name in ["low-eb-120", "run_1.csv", "a.b-c_D9"] {
            safe_file_name(name).unwrap();
        }
        assert!(!dir.join("escape").exists() && !dir.join("report/eb").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
