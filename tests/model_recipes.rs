//! The model-output recipes' own checks: `scripts/export_normals_metric3d.py --self-test` (the
//! normal frame fit, facing, EXR round trip) and `scripts/export_arch_sam3.py --self-test` (the
//! prompt table, painting order, PNG round trip). Neither needs model weights; both need numpy.
//!
//! Without python3 or numpy these tests say they are skipped and return, except where `CI` is
//! `true` (.ci/run installs numpy): there a skip is not a pass, so they fail saying why.

use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// Whether the self-tests can run here; panics in CI when they cannot.
fn python_with_numpy() -> bool {
    let why = match Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
    {
        Ok(o) if o.status.success() => return true,
        Ok(o) => format!(
            "numpy is not importable ({})",
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => format!("python3 could not be started ({e})"),
    };
    if matches!(std::env::var("CI").as_deref(), Ok("true")) {
        panic!("{why}, so the model recipes' self-tests did not run; CI must run them");
    }
    eprintln!("skipped: {why}; the model recipes' self-tests did not run");
    false
}

fn self_test(script: &str) {
    if !python_with_numpy() {
        return;
    }
    let out = Command::new("python3")
        .args([script, "--self-test"])
        .current_dir(ROOT)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .unwrap();
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success() && text.contains("self-test passed"),
        "{script} --self-test failed ({}):\n{text}",
        out.status
    );
}

#[test]
fn metric3d_normals_recipe_self_test() {
    self_test("scripts/export_normals_metric3d.py");
}

#[test]
fn sam3_prompts_recipe_self_test() {
    self_test("scripts/export_arch_sam3.py");
}
