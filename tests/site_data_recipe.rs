//! Runs `python3 -m unittest tests/site_data_recipe.py`: scripts/site_data.py against the recorded
//! responses in tests/fixtures/site_data, for every site, with no network.
//!
//! Without python3 the test says it is skipped and returns, except where `CI` is `true`: there a
//! skip is not a pass, so it fails saying why.

use std::process::Command;

#[test]
fn site_data_recipe_replays_every_site() {
    let out = match Command::new("python3")
        .args(["-m", "unittest", "tests/site_data_recipe.py"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
    {
        Ok(out) => out,
        Err(e) => {
            if matches!(std::env::var("CI").as_deref(), Ok("true")) {
                panic!(
                    "python3 could not be started ({e}), so tests/site_data_recipe.py did not run; \
                     CI must run it: install Python 3.11 or later"
                );
            }
            eprintln!(
                "skipped: python3 could not be started ({e}); tests/site_data_recipe.py did not run"
            );
            return;
        }
    };
    assert!(
        out.status.success(),
        "python3 -m unittest tests/site_data_recipe.py failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
