//! Files jem must never replace, locks that must hold across containers, signals and time limits (and never make
//! a run wait on a FIFO), and messages that say what is wrong, each checked with the command lines of its case.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{files_in, jem, run_in, stderr};

/// Renders a synthetic scene into `dir/name` (`W×H`, ndisp `n`).
fn synth(dir: &Path, name: &str, size: (u32, u32), ndisp: u32, seed: u32) -> PathBuf {
    let (w, h, n, s) = (size.0.to_string(), size.1.to_string(), ndisp.to_string(), seed.to_string());
    let out = run_in(dir, &["synth", name, "--width", &w, "--height", &h, "--ndisp", &n, "--seed", &s, "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    dir.join(name)
}

/// A KITTI 2015 tree at `dir/tree` with frames 000000_10, 000001_10, … from 64 × 48 synthetic scenes (their
/// ground truth in `disp_noc_0/`).
fn kitti(dir: &Path, tree: &str, frames: u32) -> PathBuf {
    let tree = dir.join(tree);
    for sub in ["image_2", "image_3", "disp_noc_0"] {
        std::fs::create_dir_all(tree.join(sub)).unwrap();
    }
    for k in 0..frames {
        let scene = dir.join(format!("kitti-scene-{k}"));
        if !scene.is_dir() {
            synth(dir, &format!("kitti-scene-{k}"), (64, 48), 16, k + 1);
        }
        let frame = format!("{k:06}_10.png");
        std::fs::copy(scene.join("im0.png"), tree.join("image_2").join(&frame)).unwrap();
        std::fs::copy(scene.join("im1.png"), tree.join("image_3").join(&frame)).unwrap();
        let truth = jem::io::pfm::read_pfm(&scene.join("disp0GT.pfm")).unwrap();
        jem::io::write_disparity(&tree.join("disp_noc_0").join(&frame), &truth).unwrap();
    }
    tree
}

/// The kind of file at `path` (not following a last symbolic link).
fn kind(path: &Path) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let Ok(meta) = std::fs::symlink_metadata(path) else { return "missing" };
    let t = meta.file_type();
    match () {
        _ if t.is_symlink() => "symlink",
        _ if t.is_fifo() => "fifo",
        _ if t.is_char_device() => "char device",
        _ if t.is_dir() => "folder",
        _ => "file",
    }
}

/// Special files named `NAME.ext` in `dir`: a FIFO, a symbolic link to `/dev/null`, and a device node (the
/// character device 1,3 that /dev/null is) where this process may make one; with their kinds.
fn special_files(dir: &Path, ext: &str) -> Vec<(PathBuf, &'static str)> {
    let fifo = dir.join(format!("fifo.{ext}"));
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let link = dir.join(format!("null.{ext}"));
    std::os::unix::fs::symlink("/dev/null", &link).unwrap();
    let mut made = vec![(fifo, "fifo"), (link, "symlink")];
    let node = dir.join(format!("mynull.{ext}"));
    if Command::new("mknod").arg(&node).args(["c", "1", "3"]).output().is_ok_and(|o| o.status.success()) {
        made.push((node, "char device"));
    }
    made
}

/// Runs `cmd` to its end, or fails the test if it takes more than `limit` (killing it).
fn output_within(cmd: &mut Command, limit: Duration) -> std::process::Output {
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            child.kill().unwrap();
            let out = child.wait_with_output().unwrap();
            panic!("still running after {limit:?} (killed): {}", stderr(&out));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// Waits until `path` exists (a lock, a temporary tree), failing the test if `child` ends first.
fn wait_for(path: &Path, child: &mut Child) {
    let start = Instant::now();
    while std::fs::symlink_metadata(path).is_err() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("{} never appeared; the run ended first ({status})", path.display());
        }
        assert!(start.elapsed() < Duration::from_secs(120), "{} never appeared", path.display());
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Sends `signal` (`TERM`, `INT`) to a process.
fn send(signal: &str, child: &Child) {
    let ok = Command::new("kill").arg(format!("-{signal}")).arg(child.id().to_string()).status().unwrap();
    assert!(ok.success());
}

/// A scene large enough that a batch over it with one thread runs for several seconds.
fn slow_scene(dir: &Path) -> PathBuf {
    synth(dir, "slow/S", (960, 720), 96, 3)
}

/// The names under `dir` that jem makes only while it works: temporary files and trees, and locks.
fn leftovers(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.contains(".jem-tmp") || name.starts_with(".jem-lock") || name.starts_with(".jem-stale") {
                found.push(e.path().display().to_string());
            }
            if e.file_type().unwrap().is_dir() {
                stack.push(e.path());
            }
        }
    }
    found
}

/// `jem L R -o dev.pfm` (also `--confidence`, `--depth`, `--cloud`, `viz -o`, and a batch's result files) where
/// the output is a FIFO, a link to `/dev/null` or a device node: a rename would put a plain file in its place (as
/// root, in place of /dev/null itself). Refused before any work, naming the file; the special file is left as it
/// is and nothing else is written. `-o /dev/stdout` is refused too (a stream cannot be written all or none).
#[test]
fn outputs_never_replace_a_device_node_or_a_fifo() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    synth(d, "S", (64, 48), 16, 1);
    let (l, r) = ("S/im0.png", "S/im1.png");
    let out = run_in(d, &[l, r, "-o", "ok.pfm", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let mut cases: Vec<(Vec<String>, PathBuf, &str)> = Vec::new();
    for (ext, args) in [
        ("pfm", vec![l, r, "-o", "{}"]),
        ("pfm", vec![l, r, "-o", "a.pfm", "--confidence", "{}"]),
        ("pfm", vec![l, r, "-o", "a.pfm", "--depth", "{}"]),
        ("ply", vec![l, r, "-o", "a.pfm", "--cloud", "{}"]),
        ("png", vec!["viz", "ok.pfm", "-o", "{}"]),
    ] {
        let sub = d.join(format!("case{}", cases.len()));
        std::fs::create_dir(&sub).unwrap();
        for (special, was) in special_files(&sub, ext) {
            let name = special.to_str().unwrap().to_string();
            cases.push((args.iter().map(|a| a.replace("{}", &name)).collect(), special, was));
        }
    }
    for (args, special, was) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = run_in(d, &args);
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {text}");
        assert!(text.lines().count() == 1 && text.contains("not a regular file"), "{args:?}: {text}");
        assert!(text.contains(&*special.to_string_lossy()), "{args:?}: {text}");
        assert_eq!(kind(special), *was, "{args:?}: {} replaced", special.display());
        assert!(!d.join("a.pfm").exists(), "{args:?}: the other output written");
    }
    assert_eq!(kind(Path::new("/dev/null")), "char device");
    let out = run_in(d, &[l, r, "-o", "/dev/stdout"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));

    // In a batch: the scene whose result is a FIFO (or whose time file is a link to /dev/null) fails alone.
    synth(d, "set/a", (64, 48), 16, 2);
    synth(d, "set/b", (64, 48), 16, 3);
    synth(d, "set/c", (64, 48), 16, 4);
    assert!(Command::new("mkfifo").arg(d.join("set/a/disp0A.pfm")).status().unwrap().success());
    std::os::unix::fs::symlink("/dev/null", d.join("set/b/timeA.txt")).unwrap();
    let out = output_within(
        jem().current_dir(d).args(["batch", "set", "--alg", "A", "--set", "model=wta"]),
        Duration::from_secs(120),
    );
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("set/a/disp0A.pfm: is a FIFO (named pipe), not a regular file"), "{text}");
    assert!(text.contains("set/b/timeA.txt: is a character device, not a regular file"), "{text}");
    assert_eq!((kind(&d.join("set/a/disp0A.pfm")), kind(&d.join("set/b/timeA.txt"))), ("fifo", "symlink"));
    assert!(!d.join("set/a/timeA.txt").exists() && !d.join("set/b/disp0A.pfm").exists(), "all or none");
    assert!(d.join("set/c/disp0A.pfm").is_file(), "the other scene still runs");
    assert!(leftovers(d).is_empty(), "{:?}", leftovers(d));
}

/// Batch A runs in another PID namespace (`unshare --pid --fork --mount-proc`, as in a container sharing the
/// host's name): it is pid 1 there, and pid 1 on the host is another process, so B must not take A's lock for a
/// stale one and write the same results beside it. The lock records A's namespace; B, in another, cannot tell,
/// and is refused. (Where `unshare` is not allowed, a lock naming another namespace is written by hand instead.)
#[test]
fn a_live_batch_in_another_pid_namespace_keeps_its_lock() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = slow_scene(d);
    let lock = scene.join(".jem-lock-A");
    let batch = |alg: &str, set: &str| {
        vec!["batch".to_string(), "slow".into(), "--alg".into(), alg.into(), "--set".into(), set.into()]
    };
    let unshare_works = Command::new("unshare")
        .args(["--pid", "--fork", "--mount-proc", "true"])
        .output()
        .is_ok_and(|o| o.status.success());
    let mut a = if unshare_works {
        let child = Command::new("unshare")
            .args(["--pid", "--fork", "--mount-proc", "--kill-child"])
            .arg(env!("CARGO_BIN_EXE_jem"))
            .args(batch("A", "post.fill=true"))
            .args(["--threads", "1", "-q"])
            .current_dir(d)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        Some(child)
    } else {
        eprintln!("note: unshare --pid is not allowed here; the other namespace's lock is written by hand");
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
        let host: String =
            host.trim().chars().filter(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '.')).collect();
        std::fs::write(&lock, format!("pid 1\nhost {host}\nstart 1\npidns pid:[1]\n")).unwrap();
        None
    };
    if let Some(a) = &mut a {
        wait_for(&lock, a);
    }
    // Made empty, then written: read once it names its host.
    let start = Instant::now();
    let mut lock_text = String::new();
    while !lock_text.contains("host ") && start.elapsed() < Duration::from_secs(10) {
        lock_text = std::fs::read_to_string(&lock).unwrap_or_default();
        std::thread::sleep(Duration::from_millis(2));
    }
    let args = batch("A", "post.fill=false");
    let out = output_within(jem().current_dir(d).args(&args), Duration::from_secs(300));
    let a_was_running = a.as_mut().is_none_or(|a| a.try_wait().unwrap().is_none());
    if let Some(a) = &mut a {
        a.kill().unwrap();
        a.wait().unwrap();
    }
    let text = stderr(&out);
    assert!(!text.contains("took over"), "{text}");
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("another jem run (pid 1 on") && text.contains("is writing these results"), "{text}");
    assert!(a_was_running, "batch A ended before B was checked: the scene is too small");
    // A is pid 1 of its namespace, which the lock records: not this process's.
    let ours = std::fs::read_link("/proc/self/ns/pid").unwrap();
    assert!(lock_text.starts_with("pid 1\n") && lock_text.contains("pidns pid:["), "{lock_text}");
    assert!(!lock_text.contains(&format!("pidns {}", ours.display())), "{lock_text}");
}

/// `jem synth DIR` into a copy of a scene would replace its images, ground truth and calib.txt and leave its old
/// `disp0J.pfm` beside them: a folder that holds scene files is refused, as `jem degrade` refuses one that is not
/// empty, and nothing in it changes. A folder without scene files (or a new one) is fine.
#[test]
fn synth_refuses_a_folder_that_holds_a_scene() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let teddy = d.join("Teddy");
    match common::data_dir().map(|data| data.join("MiddEval3/trainingQ/Teddy")).filter(|t| t.is_dir()) {
        Some(source) => {
            std::fs::create_dir(&teddy).unwrap();
            for f in ["im0.png", "im1.png", "calib.txt", "disp0GT.pfm", "mask0nocc.png"] {
                std::fs::copy(source.join(f), teddy.join(f)).unwrap();
            }
        }
        None => {
            synth(d, "Teddy", (64, 48), 16, 9);
        }
    }
    std::fs::write(teddy.join("disp0J.pfm"), b"an old result").unwrap();
    let before: Vec<(String, Vec<u8>)> =
        files_in(&teddy).into_iter().map(|f| (f.clone(), std::fs::read(teddy.join(&f)).unwrap())).collect();
    let out = run_in(d, &["synth", "Teddy", "--width", "64", "--height", "48", "--ndisp", "16"]);
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert_eq!(text.lines().count(), 1, "{text}");
    assert!(text.contains("Teddy: already holds a scene (calib.txt, disp0GT.pfm, disp0J.pfm, im0.png"), "{text}");
    let after: Vec<(String, Vec<u8>)> =
        files_in(&teddy).into_iter().map(|f| (f.clone(), std::fs::read(teddy.join(&f)).unwrap())).collect();
    assert!(before == after, "the scene folder changed");
    // A folder holding other files only, or a result alone, is judged by its scene files.
    std::fs::create_dir(d.join("notes")).unwrap();
    std::fs::write(d.join("notes/README"), b"x").unwrap();
    assert!(run_in(d, &["synth", "notes", "--width", "64", "--height", "48", "--ndisp", "16"]).status.success());
    std::fs::create_dir(d.join("stale")).unwrap();
    std::fs::write(d.join("stale/timeA.txt"), b"1.0\n").unwrap();
    assert_eq!(run_in(d, &["synth", "stale", "--width", "64", "--height", "48"]).status.code(), Some(2));
}

/// `kill -TERM` (Slurm at a task's time limit) or Ctrl-C during a batch: a lock left behind would refuse the
/// resubmitted task on another node. The run removes its locks and unfinished files, says so, and exits 143
/// (SIGTERM) or 130 (SIGINT), leaving no partial result. The same for `jem degrade`'s temporary tree.
#[test]
fn a_signal_releases_the_locks_and_leaves_no_partial_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = slow_scene(d);
    for (signal, code) in [("TERM", 143), ("INT", 130)] {
        let mut child = jem()
            .current_dir(d)
            .args(["batch", "slow", "--alg", "A", "--threads", "1"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        wait_for(&scene.join(".jem-lock-A"), &mut child);
        send(signal, &child);
        let out = child.wait_with_output().unwrap();
        assert_eq!(out.status.code(), Some(code), "SIG{signal}: {}", stderr(&out));
        assert!(stderr(&out).contains(&format!("error: stopped by SIG{signal}")), "{}", stderr(&out));
        assert!(leftovers(d).is_empty(), "SIG{signal}: {:?}", leftovers(d));
        assert!(!scene.join("disp0A.pfm").exists() && !scene.join("timeA.txt").exists(), "SIG{signal}");
    }
    // `jem degrade`: its temporary tree goes too.
    let mut child = jem()
        .current_dir(d)
        .args(["degrade", "slow", "out", "--recipe", "blur:2+noise:3", "--threads", "1"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !files_in(d).iter().any(|n| n.starts_with(".out.jem-tmp")) {
        assert!(child.try_wait().unwrap().is_none(), "degrade ended before its temporary tree was seen");
        assert!(start.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(5));
    }
    send("TERM", &child);
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(143), "{}", stderr(&out));
    assert!(leftovers(d).is_empty() && !d.join("out").exists(), "{:?}", files_in(d));
}

/// A Slurm task killed on node-a left `.jem-lock-3-of-4`; the same task of the same job, requeued (Slurm's restart
/// count one higher), lands on another node, where another host's lock cannot be checked. A rerun of the same
/// job's same shard takes over its own lock, with a note (Slurm runs a job once at a time); a run of another job,
/// or of the same run count, is refused: "another jem run (pid 6302 on node-a) is writing these results".
#[test]
fn a_rerun_of_the_same_slurm_task_takes_over_its_own_lock() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tree = kitti(d, "k/training", 4);
    let out = run_in(d, &["batch", "k/training", "--alg", "A", "--set", "model=wta", "--shard", "1/4", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let results = d.join("k/results/A/training");
    let lock = results.join(".jem-lock-3-of-4");
    let left = "pid 6302\nhost node-a\nstart 1\npidns pid:[4026531836]\nslurm-job 77_3\nslurm-restart 0\nshard 3/4\n";
    let task = |job: &str, task: &str, restart: &str| {
        let mut cmd = Command::new(common::repo().join("scripts/slurm-batch.sh"));
        cmd.current_dir(d)
            .args([tree.to_str().unwrap(), "--alg", "A", "--set", "model=wta"])
            .env("JEM", env!("CARGO_BIN_EXE_jem"))
            .env("SLURM_ARRAY_JOB_ID", job)
            .env("SLURM_ARRAY_TASK_ID", task)
            .env("SLURM_ARRAY_TASK_MIN", "1")
            .env("SLURM_ARRAY_TASK_MAX", "4")
            .env("SLURM_RESTART_COUNT", restart)
            .env_remove("SLURM_JOB_ID");
        output_within(&mut cmd, Duration::from_secs(120))
    };
    for (job, restart) in [("77", "0"), ("78", "1")] {
        std::fs::write(&lock, left).unwrap();
        let out = task(job, "3", restart);
        assert_eq!(out.status.code(), Some(2), "job {job} restart {restart}: {}", stderr(&out));
        assert!(stderr(&out).contains("another jem run (pid 6302 on node-a)"), "{}", stderr(&out));
        assert_eq!(std::fs::read_to_string(&lock).unwrap(), left);
    }
    let out = task("77", "3", "1");
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("took over the lock of pid 6302 on node-a, an earlier run of this Slurm job (77_3)"),
        "{}",
        stderr(&out)
    );
    assert!(results.join("disp_0/000002_10.png").is_file());
    assert!(leftovers(d).is_empty(), "{:?}", leftovers(d));
}

/// A lock that is a folder, a dangling symbolic link, not UTF-8, or a FIFO (which a plain read waits on until a
/// writer comes): each is named with what it is, only its scene fails (the others run), nothing waits, and
/// `eval` warns about each, as `batch` refuses it.
#[test]
fn unreadable_locks_fail_their_scene_and_never_hang() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (k, scene) in ["a", "b", "c", "d", "e"].iter().enumerate() {
        synth(d, &format!("set/{scene}"), (64, 48), 16, k as u32 + 1);
    }
    let lock = |s: &str| d.join("set").join(s).join(".jem-lock-A");
    std::fs::create_dir(lock("a")).unwrap();
    std::os::unix::fs::symlink("gone", lock("b")).unwrap();
    std::fs::write(lock("c"), b"pid 12\nhost \xff\xfe\n").unwrap();
    assert!(Command::new("mkfifo").arg(lock("d")).status().unwrap().success());
    let out = output_within(
        jem().current_dir(d).args(["batch", "set", "--alg", "A", "--set", "model=wta"]),
        Duration::from_secs(60),
    );
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{text}");
    for (scene, why) in [
        ("a", "it is a folder"),
        ("b", "it is a symbolic link"),
        ("c", "it is not UTF-8 text"),
        ("d", "it is a FIFO (named pipe), not a regular file"),
    ] {
        let line = format!("set/{scene}/.jem-lock-A: this lock cannot be read ({why})");
        assert!(text.contains(&line), "{line}: {text}");
        assert!(!d.join("set").join(scene).join("disp0A.pfm").exists());
    }
    assert!(!text.contains("at the same time"), "{text}");
    assert!(d.join("set/e/disp0A.pfm").is_file(), "the other scene runs: {text}");
    assert_eq!(kind(&lock("d")), "fifo");
    let out = output_within(
        jem().current_dir(d).args(["eval", "set", "--alg", "A", "--scale", "1"]),
        Duration::from_secs(60),
    );
    let text = stderr(&out);
    for scene in ["a", "b", "c", "d"] {
        let line = format!("set/{scene}: a run may be writing these results: its lock .jem-lock-A cannot be read");
        assert!(text.contains(&line), "{line}: {text}");
    }
}

/// A FIFO where an input is read never makes a command wait for a writer: a result `jem batch --skip-existing`
/// checks (a FIFO `disp0Q.pfm`), a calibration (`jem rectify`, `--rectify`), a config (`-c`), an image. Each is
/// refused at once, naming the file, and left as it is.
#[test]
fn a_fifo_input_is_refused_not_waited_on() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    synth(d, "set/a", (64, 48), 16, 1);
    synth(d, "set/b", (64, 48), 16, 2);
    let fifo = |p: &Path| assert!(Command::new("mkfifo").arg(p).status().unwrap().success());
    fifo(&d.join("set/a/disp0Q.pfm"));
    let out = output_within(
        jem().current_dir(d).args(["batch", "set", "--alg", "Q", "--skip-existing", "--set", "model=wta"]),
        Duration::from_secs(60),
    );
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("set/a/disp0Q.pfm: is a FIFO (named pipe), not a regular file"), "{text}");
    assert!(d.join("set/b/disp0Q.pfm").is_file(), "the other scene runs: {text}");
    assert_eq!(kind(&d.join("set/a/disp0Q.pfm")), "fifo");
    fifo(&d.join("cal.yml"));
    fifo(&d.join("c.toml"));
    std::fs::create_dir(d.join("c")).unwrap();
    fifo(&d.join("c/im1.png"));
    let cases: [(&[&str], &str); 4] = [
        (&["rectify", "cal.yml", "set/b/im0.png", "set/b/im1.png", "-o", "r"], "cal.yml"),
        (&["set/b/im0.png", "set/b/im1.png", "--rectify", "cal.yml", "-o", "r.pfm"], "cal.yml"),
        (&["set/b/im0.png", "set/b/im1.png", "-c", "c.toml", "-o", "r.pfm"], "c.toml"),
        (&["set/b/im0.png", "c/im1.png", "-o", "r.pfm", "--ndisp", "16"], "c/im1.png"),
    ];
    for (args, name) in cases {
        let out = output_within(jem().current_dir(d).args(args), Duration::from_secs(60));
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {text}");
        assert!(text.contains(&format!("{name}: is a FIFO (named pipe), not a regular file")), "{args:?}: {text}");
    }
    assert!(!d.join("r").exists() && !d.join("r.pfm").exists());
    assert_eq!((kind(&d.join("cal.yml")), kind(&d.join("c/im1.png"))), ("fifo", "fifo"));
}

/// Results accepted by their data set's fingerprint after a move: if `source.txt` kept naming the old folder, they
/// would be "the results of /…/MV1/training" (gone) once the data set grows and its fingerprint changes. The batch
/// that accepts a moved tree rewrites `source.txt` (atomically) to name where it is.
#[test]
fn a_moved_data_set_is_named_in_its_results_source_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    kitti(d, "MV1/training", 1);
    let batch = |tree: &str| {
        run_in(d, &["batch", tree, "--alg", "A", "--results", "R", "--set", "model=wta", "--skip-existing", "-q"])
    };
    assert!(batch("MV1/training").status.success());
    std::fs::rename(d.join("MV1"), d.join("MV2")).unwrap();
    let out = batch("MV2/training");
    assert!(out.status.success(), "accepted by its fingerprint: {}", stderr(&out));
    let source = std::fs::read_to_string(d.join("R/A/training/source.txt")).unwrap();
    assert!(source.contains("root ../../../MV2/training\n"), "{source}");
    // The data set grows: its results are still its own, and the new frame is added.
    kitti(d, "MV2/training", 2);
    let out = batch("MV2/training");
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(d.join("R/A/training/disp_0/000001_10.png").is_file());
    assert_eq!(files_in(&d.join("R/A/training")), ["config", "disp_0", "source.txt", "time"]);
}

/// An argument error is one `error:` line, as every other error (not clap's 3 to 6: a tip, the usage, "For more
/// information, try '--help'."); `--help` still prints the help.
#[test]
fn argument_errors_are_one_line() {
    let dir = tempfile::tempdir().unwrap();
    for (args, says) in [
        (&["--bogus"][..], "error: unexpected argument '--bogus' found"),
        (&["batch"], "error: the following required arguments were not provided: --alg <NAME>, <DIR>..."),
        (&["config", "--seta", "x=1"], "a similar argument exists: '--set'"),
        (&["batch", "d", "--alg", "A", "--threads", "x"], "error: invalid value 'x' for '--threads <N>'"),
        (&["a.png", "b.png", "-o"], "error: a value is required for '--output <OUT>'"),
    ] {
        let out = run_in(dir.path(), args);
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {text}");
        assert!(text.lines().count() == 1 && text.starts_with("error: ") && text.contains(says), "{args:?}: {text}");
    }
    let out = run_in(dir.path(), &["batch", "--help"]);
    assert!(out.status.success() && String::from_utf8_lossy(&out.stdout).contains("Usage: jem batch"));
}

/// `--set meanfield.iterations=1e30`: the message says what the key takes and quotes the value as given (not
/// "invalid type: floating point `1000000000000000000000000000000.0`, expected usize").
#[test]
fn a_value_of_the_wrong_type_says_what_the_key_takes() {
    let dir = tempfile::tempdir().unwrap();
    for (set, says) in [
        (
            "meanfield.iterations=1e30",
            "error: --set: `meanfield.iterations` takes a whole number >= 0 (like 5), not 1e30",
        ),
        ("post.fill=3", "error: --set: `post.fill` takes true or false, not 3"),
    ] {
        let out = run_in(dir.path(), &["config", "--set", set]);
        assert_eq!((out.status.code(), stderr(&out)), (Some(2), format!("{says}\n")));
    }
}

/// An empty or garbage `source.txt` in a results folder names no data set: it is named as unreadable, with what
/// would fix it, not taken for "the results of another data set".
#[test]
fn an_empty_or_garbage_source_file_is_named_as_unreadable() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    kitti(d, "k/training", 1);
    let out = run_in(d, &["batch", "k/training", "--alg", "A", "--set", "model=wta", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let source = d.join("k/results/A/training/source.txt");
    for (bytes, why) in [
        (&b""[..], "no layout line"),
        (b"\x89PNG\r\n\x1a\n\0\0", "no layout line"),
        (b"layout mars\nroot x\n", "unknown layout"),
    ] {
        std::fs::write(&source, bytes).unwrap();
        for cmd in [&["batch", "k/training", "--alg", "A"][..], &["eval", "k/training", "--alg", "A"]] {
            let out = run_in(d, cmd);
            let text = stderr(&out);
            assert_eq!(out.status.code(), Some(2), "{cmd:?}: {text}");
            assert!(text.contains(&format!("source.txt: unreadable ({why}")), "{cmd:?}: {text}");
            assert!(!text.contains("holds the results of"), "{cmd:?}: {text}");
        }
        assert_eq!(std::fs::read(&source).unwrap(), bytes, "left as it is");
    }
}

/// `jem eval`'s closing line tells scenes without a usable result from scenes whose mask or calib.txt is missing,
/// as the list above it does.
#[test]
fn eval_says_when_the_ground_truth_or_calib_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (k, scene) in ["ok", "nomask", "nocalib", "noresult"].iter().enumerate() {
        synth(d, &format!("set/{scene}"), (64, 48), 16, k as u32 + 1);
    }
    let out = run_in(d, &["batch", "set", "--alg", "A", "--set", "model=wta", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::remove_file(d.join("set/nomask/mask0nocc.png")).unwrap();
    std::fs::remove_file(d.join("set/nocalib/calib.txt")).unwrap();
    std::fs::remove_file(d.join("set/noresult/disp0A.pfm")).unwrap();
    let out = run_in(d, &["eval", "set", "--alg", "A", "--scale", "1"]);
    let (listed, text) = (String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    let last = text.lines().last().unwrap();
    assert!(
        last.ends_with(
            "; 1 without a usable result, 2 without a usable ground truth, mask or calib.txt (listed above)"
        ),
        "{last}"
    );
    assert!(listed.contains("nomask: no set/nomask/mask0nocc.png (needed for the nonocc mask)"), "{listed}");
    assert!(listed.contains("nocalib: no set/nocalib/calib.txt (needed for the search range)"), "{listed}");
    assert!(listed.contains("noresult: no result file set/noresult/disp0A.pfm"), "{listed}");
}
