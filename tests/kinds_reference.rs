//! `kodama-dag kinds KIND` (issue 55, class 8): every param of every kind with its type, its
//! default and its documentation, read from the stage's own source, so users need not provoke
//! errors to learn a kind's params.

mod common;
use common::*;

use kodama_dag::cli::kinds::{defaults_of, kind_reference};
use kodama_dag::registry;
use kodama_nodes::params::reference;

/// Every kind's params type is in the reference, with a doc comment on every field, and every
/// type a field names resolves: the build script read every file a stage lives in.
#[test]
fn every_param_of_every_kind_is_documented() {
    let mut undocumented = Vec::new();
    for k in registry::kinds() {
        let Some(params) = reference::of_path((k.params_type)()) else {
            panic!("{}: no reference for {}", k.name, (k.params_type)());
        };
        let mut pending = vec![params];
        let mut seen = Vec::new();
        while let Some(ty) = pending.pop() {
            if seen.iter().any(|s| std::ptr::eq(*s, ty)) {
                continue;
            }
            seen.push(ty);
            for f in ty.fields.iter().filter(|f| f.doc.trim().is_empty()) {
                undocumented.push(format!("{}: {}.{}", k.name, ty.name, f.name));
            }
            for f in ty.fields {
                pending.extend(reference::named_in(f.ty, ty.module));
            }
        }
    }
    undocumented.sort();
    undocumented.dedup();
    assert!(
        undocumented.is_empty(),
        "params without a doc comment: {undocumented:#?}"
    );
}

/// The reference's field names are the parser's: every field the kind's parsed params report is
/// one the reference lists as optional, and every listed field is printed.
#[test]
fn the_reference_lists_the_fields_the_parser_knows() {
    let mut with_defaults = 0;
    for k in registry::kinds() {
        let text = kind_reference(k);
        let params = reference::of_path((k.params_type)()).unwrap();
        if let Some(defaults) = defaults_of(k, params) {
            with_defaults += 1;
            for name in defaults.keys() {
                assert!(
                    params.fields.iter().any(|f| f.name == name && f.optional),
                    "{}: the parser has field {name}, the reference no optional one of that name",
                    k.name
                );
            }
        }
        for f in params.fields {
            assert!(
                text.contains(&format!("\n  {}: ", f.name)),
                "{}: field {} not printed:\n{text}",
                k.name,
                f.name
            );
        }
    }
    // Most kinds' required params are numbers, strings and tuples a placeholder can stand for.
    assert!(
        with_defaults * 10 >= registry::kinds().len() * 8,
        "defaults read for only {with_defaults} kinds"
    );
}

#[test]
fn kinds_radio_map_gives_defaults_units_and_conventions() {
    let env = Env::new();
    let r = env.cli(&["kinds", "RadioMap"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    for needle in [
        "RadioMap (version",
        "scene: Scene",
        "tx: (f64, f64, f64), required",
        "above the terrain when a\n      terrain is given",
        "cell_m: f64 = 5.0",
        "height_m: f64 = 1.5",
        "extrapolate: bool = false",
        "reach_m: Option<f64> = none",
        // Nested params, with the defaults their parent's default gives them.
        "struct MapOptions:",
        "max_depth: u32 = 3",
        "rays: u32 = 1000000",
        "struct Antenna:",
        "pattern: Pattern = Isotropic",
        "degrees clockwise from grid north",
        "enum Device:",
        "Directive(alpha_r: u32)",
    ] {
        assert!(
            r.stdout.contains(needle),
            "{needle:?} missing in:\n{}",
            r.stdout
        );
    }
}

#[test]
fn kinds_of_an_unknown_kind_suggests_the_nearest() {
    let env = Env::new();
    let r = env.cli(&["kinds", "RadioMpa"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("no node kind \"RadioMpa\"; did you mean \"RadioMap\"?"),
        "{}",
        r.stderr
    );
    assert!(r.stdout.is_empty());
}

#[test]
fn kinds_lists_every_kind_and_points_at_the_reference() {
    let env = Env::new();
    let r = env.cli(&["kinds"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    for k in registry::kinds() {
        assert!(r.stdout.contains(&format!("{} v{}", k.name, k.version)));
    }
    assert!(r.stdout.contains("kodama-dag kinds KIND"));
}
