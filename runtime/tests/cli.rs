//! The `grotto` binary as a user runs it: inspect (text and JSON) and verify (exit codes).

use std::process::Command;

use grotto_preprocess::demo::{self, DemoParams};

fn grotto(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_grotto")).args(args).output().unwrap()
}

#[test]
fn inspect_and_verify_a_demo_package() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.grotto");
    demo::build(&path, &DemoParams { points: 5_000, ..DemoParams::default() }).unwrap();
    let p = path.to_str().unwrap();

    let out = grotto(&["inspect", p, "--sections"]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("grotto package 1.0") && text.contains("surfel-colors-raw"), "{text}");
    assert!(text.contains("cameras [centre]"), "{text}");

    let out = grotto(&["inspect", p, "--json"]);
    assert!(out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["version"], "1.0");
    assert_eq!(json["tiles"]["points"], 5_000);
    assert_eq!(json["scene"]["lights"][0]["name"], "lantern");
    assert!(json["sections"].as_array().unwrap().len() >= 3);

    let out = grotto(&["verify", p]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    // One flipped payload byte: verify fails and names the section.
    let mut bytes = std::fs::read(&path).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let out = grotto(&["verify", p, "--json"]);
    assert!(!out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let problem = json["problems"][0].as_str().unwrap();
    assert!(problem.contains("checksum mismatch") && problem.contains("section"), "{problem}");

    // Truncated: the package does not open, verify says why.
    std::fs::write(&path, &bytes[..bytes.len() - 100]).unwrap();
    let out = grotto(&["verify", p]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("truncated") && err.contains("demo.grotto"), "{err}");

    let out = grotto(&["inspect", "/nonexistent.grotto"]);
    assert!(!out.status.success());
    assert!(String::from_utf8(out.stderr).unwrap().contains("/nonexistent.grotto"));
}
