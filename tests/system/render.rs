//! Issue 24: `grains render --every K` of a real run draws every K-th frame and, with ffmpeg,
//! films them; `--colour strain` draws a run's incremental strain. (The pixels of a drawing are checked by `grains_launch::render`'s unit tests.)

use grains_system_tests::*;
use std::process::Command;
use std::time::Duration;

#[test]
fn render_every_other_frame_of_a_hybrid_run_draws_them_and_films_them() {
    debian("ffmpeg", "-version", "ffmpeg");
    let _machine = machine();
    let out = out_dir("render-every");
    let mut run = Running::grains(&[
        "run",
        "tests/scenes/hybrid_small_2d.toml",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
        "--set",
        "run.steps=100",
        "--set",
        "output.frames_every=20",
    ]);
    assert!(run.wait_exit(Duration::from_secs(120)).success(), "{}", run.stderr());
    let dir = run_dir(&run.stderr());
    let render = Command::new(bin("grains"))
        .args([
            "render",
            dir.to_str().unwrap(),
            "--every",
            "2",
            "--colour",
            "speed",
            "--width",
            "301",
        ])
        .output()
        .expect("grains render");
    assert!(render.status.success(), "{}", String::from_utf8_lossy(&render.stderr));
    // Frames at steps 0, 20, ..., 100: every other one is 0, 40, 80.
    let printed: Vec<String> = String::from_utf8_lossy(&render.stdout).lines().map(String::from).collect();
    let expected: Vec<String> = ["frame_00000000.png", "frame_00000040.png", "frame_00000080.png", "render.mp4"]
        .iter()
        .map(|f| dir.join("render").join(f).display().to_string())
        .collect();
    assert_eq!(printed, expected);
    let png = std::fs::read(&expected[0]).unwrap();
    assert_eq!(&png[1..4], b"PNG", "not a PNG");
    // The film: H.264, one frame per picture, the odd width padded to an even one.
    let probe = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-count_frames",
            "-show_entries",
            "stream=codec_name,width,nb_read_frames",
            "-of",
            "csv=p=0",
        ])
        .arg(&expected[3])
        .output()
        .expect("ffprobe");
    assert_eq!(String::from_utf8_lossy(&probe.stdout).trim(), "h264,302,3");
    // The strain since the frame before, of the run's own grains and points (matched by the
    // ids its frames carry; the strain's arithmetic is the unit test's).
    let strain_png = out.join("strain.png");
    let strain = Command::new(bin("grains"))
        .args(["render", dir.to_str().unwrap(), "--colour", "strain", "--out"])
        .arg(&strain_png)
        .output()
        .expect("grains render --colour strain");
    assert!(strain.status.success(), "{}", String::from_utf8_lossy(&strain.stderr));
    assert_eq!(&std::fs::read(&strain_png).unwrap()[1..4], b"PNG", "not a PNG");
    std::fs::remove_dir_all(&out).unwrap();
}
