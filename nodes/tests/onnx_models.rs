//! The in-process model stages (feature `onnx`) on tiny ONNX models whose outputs are known
//! exactly (`scripts/make_tiny_onnx.py` made them, `tests/fixtures/onnx/`): segmentation into
//! instances and materials, depth in each of its meanings, the shipped label tables, and the
//! errors a user meets (a file that is not a model, an output of the wrong shape, no ONNX Runtime).
//!
//! Needs ONNX Runtime: `pip install onnxruntime`, ORT_DYLIB_PATH set (README, "Running the models
//! in process"), then `cargo test -p kodama-nodes --features onnx --test onnx_models`.
#![cfg(feature = "onnx")]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use kodama_nodes::artifact::{Instances, Intrinsics, PodVec, Pose, RMSNET_CLASSES, View, ViewSet};
use kodama_nodes::io::onnx::ImageInput;
use kodama_nodes::stage::{Slot, process_parts};
use kodama_nodes::stages::models::estimate_depth::{
    EstimateDepth, EstimateDepthParams, Predicts, Units,
};
use kodama_nodes::stages::models::segment_views::{
    ARCH_CLASSES, CLUTTER_CLASSES, LabelTable, SegmentViews, SegmentViewsParams, Target,
};
use kodama_nodes::{Artifact, Ctx, Inputs, Site, Stage, StageError};

fn model(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/onnx")
        .join(name)
}

fn site() -> Site {
    Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    }
}

const RED: [u8; 3] = [255, 0, 0];
const GREEN: [u8; 3] = [0, 255, 0];
const BLUE: [u8; 3] = [0, 0, 255];
const GREY: [u8; 3] = [100, 100, 100];

/// The colour of each block letter; the tiny segmentation models give class 0 for red, 1 for
/// green, 2 for blue and 3 for grey (no channel above 0.5).
fn colour(c: char) -> [u8; 3] {
    match c {
        'R' => RED,
        'G' => GREEN,
        'B' => BLUE,
        _ => GREY,
    }
}

/// Expands a grid of blocks (one value per block) into pixels, each block 2 x 2.
fn expand<T: Copy>(blocks: &[Vec<T>]) -> Vec<T> {
    let mut out = Vec::new();
    for row in blocks {
        let line: Vec<T> = row.iter().flat_map(|&v| [v, v]).collect();
        out.extend(&line);
        out.extend(&line);
    }
    out
}

fn grid(rows: &[&str]) -> Vec<Vec<char>> {
    rows.iter().map(|r| r.chars().collect()).collect()
}

/// One view of 2 x 2 blocks of the colours in `rows`, with the set's material table.
fn view_set(rows: &[&str], materials: &[&str]) -> ViewSet {
    let blocks = grid(rows);
    let (w, h) = (blocks[0].len() as u32 * 2, blocks.len() as u32 * 2);
    let colours: Vec<Vec<[u8; 3]>> = blocks
        .iter()
        .map(|r| r.iter().map(|&c| colour(c)).collect())
        .collect();
    let view = View {
        id: "v0".into(),
        width: w,
        height: h,
        intrinsics: Intrinsics {
            fx: 2.0 * w as f64,
            fy: 2.0 * w as f64,
            cx: w as f64 / 2.0,
            cy: h as f64 / 2.0,
        },
        pose: Pose::from_angles([0.0, 0.0, 2.0], 0.0, 0.0, 0.0),
        captured_at: None,
        pose_source: None,
        distortion: None,
        image: PodVec(expand(&colours)),
        arch: None,
        clutter: None,
        material: None,
        depth: None,
        normal: None,
    };
    let classes = materials.iter().map(|m| m.to_string()).collect();
    ViewSet::store(vec![view], classes, process_parts())
        .unwrap()
        .unwrap()
}

/// A label table file for the four classes of the tiny models.
fn table(dir: &Path, ours: [Option<&str>; 4]) -> PathBuf {
    let names = ["red", "green", "blue", "grey"];
    let entries: Vec<String> = names
        .iter()
        .zip(ours)
        .map(|(n, o)| match o {
            Some(o) => format!("(\"{n}\", Some(\"{o}\"))"),
            None => format!("(\"{n}\", None)"),
        })
        .collect();
    let path = dir.join("tiny.ron");
    std::fs::write(
        &path,
        format!("(model: \"tiny\", classes: [{}])", entries.join(", ")),
    )
    .unwrap();
    path
}

/// Plain pixel / 255 into the models, so their outputs are exact.
fn plain(size: Option<(u32, u32)>) -> ImageInput {
    ImageInput {
        size,
        mean: [0.0; 3],
        std: [1.0; 3],
        ..Default::default()
    }
}

fn seg_params(model_file: &Path, labels: &Path, target: Target) -> SegmentViewsParams {
    SegmentViewsParams {
        model: model_file.display().to_string(),
        model_data: None,
        labels: labels.display().to_string(),
        target,
        input: plain(None),
        output: None,
        min_pixels: 1,
        threads: 1,
    }
}

fn inputs(set: &ViewSet) -> Inputs {
    Inputs::new().with("views", Slot::One(Arc::new(Artifact::Views(set.clone()))))
}

/// A view set with its views' pixels read back.
#[derive(Debug)]
struct Full {
    views: Vec<View>,
    material_classes: Vec<String>,
}

fn full(set: &ViewSet) -> Full {
    Full {
        views: set.with(process_parts()).load_all().unwrap(),
        material_classes: set.material_classes.clone(),
    }
}

fn segment(p: &SegmentViewsParams, set: &ViewSet) -> Result<Full, StageError> {
    SegmentViews::validate(p).map_err(StageError::Param)?;
    let files = vec![PathBuf::from(&p.labels), PathBuf::from(&p.model)];
    SegmentViews::run(p, &inputs(set), &Ctx::new(&site(), &files)).map(|s| full(&s))
}

fn depth_params(model_file: &Path, predicts: Predicts, units: Units) -> EstimateDepthParams {
    EstimateDepthParams {
        model: model_file.display().to_string(),
        model_data: None,
        predicts,
        units,
        input: plain(None),
        output: None,
        threads: 1,
    }
}

fn estimate(p: &EstimateDepthParams, set: &ViewSet) -> Result<Full, StageError> {
    EstimateDepth::validate(p).map_err(StageError::Param)?;
    let files = vec![PathBuf::from(&p.model)];
    EstimateDepth::run(p, &inputs(set), &Ctx::new(&site(), &files)).map(|s| full(&s))
}

/// 8 x 6 pixels: red wall, green cars (three regions), blue window, grey nothing.
const SCENE: &[&str] = &["RRGB", "RRXG", "XGXG"];

fn layer(l: &Option<Instances>) -> (Vec<u16>, Vec<(u16, String)>) {
    let l = l.as_ref().expect("layer written");
    (
        l.ids.0.clone(),
        l.classes.iter().map(|(k, v)| (*k, v.clone())).collect(),
    )
}

#[test]
fn logits_become_arch_and_clutter_instances() {
    let dir = tempfile::tempdir().unwrap();
    let labels = table(
        dir.path(),
        [Some("wall"), Some("car"), Some("window"), None],
    );
    let mut p = seg_params(&model("seg_logits.onnx"), &labels, Target::Instances);
    // Half size in, nearest neighbour back: each 2 x 2 block is one model pixel.
    p.input.size = Some((4, 3));
    let out = segment(&p, &view_set(SCENE, &[])).unwrap();
    let v = &out.views[0];
    let arch = expand(&[vec![1, 1, 0, 2], vec![1, 1, 0, 0], vec![0, 0, 0, 0]]);
    assert_eq!(
        layer(&v.arch),
        (arch, vec![(1, "wall".into()), (2, "window".into())])
    );
    // Cars: the lone top block, the two joined right blocks, the lone bottom block, numbered in
    // raster order of their first pixel.
    let clutter = expand(&[vec![0, 0, 1, 0], vec![0, 0, 0, 2], vec![0, 3, 0, 2]]);
    assert_eq!(
        layer(&v.clutter),
        (
            clutter,
            vec![(1, "car".into()), (2, "car".into()), (3, "car".into())]
        )
    );
    assert_eq!(v.material, None);
    assert_eq!(v.image, full(&view_set(SCENE, &[])).views[0].image);

    // Small regions are dropped: only the 8-pixel car is left.
    p.min_pixels = 5;
    p.target = Target::Clutter;
    let out = segment(&p, &view_set(SCENE, &[])).unwrap();
    let clutter = expand(&[vec![0, 0, 0, 0], vec![0, 0, 0, 1], vec![0, 0, 0, 1]]);
    assert_eq!(
        layer(&out.views[0].clutter),
        (clutter, vec![(1, "car".into())])
    );
    assert_eq!(out.views[0].arch, None, "target Clutter leaves arch alone");
}

#[test]
fn class_ids_become_materials_appended_to_the_set_table() {
    let dir = tempfile::tempdir().unwrap();
    let labels = table(
        dir.path(),
        [Some("brick"), Some("glass"), None, Some("concrete")],
    );
    // seg_ids.onnx takes a fixed 4 x 4 input: the 8 x 8 view is halved.
    let p = seg_params(&model("seg_ids.onnx"), &labels, Target::Material);
    let rows = ["RGBX", "XXRR", "GGBB", "RXGB"];
    let out = segment(&p, &view_set(&rows, &["concrete", "metal"])).unwrap();
    assert_eq!(
        out.material_classes,
        ["concrete", "metal", "brick", "glass"]
    );
    let index = |c: char| match c {
        'R' => 2u8,
        'G' => 3,
        'B' => 255,
        _ => 0,
    };
    let expected: Vec<Vec<u8>> = grid(&rows)
        .iter()
        .map(|r| r.iter().map(|&c| index(c)).collect())
        .collect();
    assert_eq!(out.views[0].material.as_ref().unwrap().0, expand(&expected));

    // A size other than the model's fixed one is a param error.
    let mut q = p.clone();
    q.input.size = Some((8, 8));
    let e = segment(&q, &view_set(&rows, &[])).unwrap_err();
    assert!(
        matches!(&e, StageError::Param(pe) if pe.field == "input"),
        "{e}"
    );
}

/// The red channel of each pixel of `rows`, as the model sees it.
fn red(rows: &[&str]) -> Vec<f32> {
    let blocks: Vec<Vec<f32>> = grid(rows)
        .iter()
        .map(|r| r.iter().map(|&c| colour(c)[0] as f32 / 255.0).collect())
        .collect();
    expand(&blocks)
}

#[test]
fn depth_in_each_of_its_meanings() {
    let set = view_set(SCENE, &[]);
    let value: Vec<f32> = red(SCENE).iter().map(|&r| 2.0 * r + 1.0).collect();
    let depth_of = |p: EstimateDepthParams| {
        let out = estimate(&p, &set).unwrap();
        let v = &out.views[0];
        assert_eq!(v.image, full(&set).views[0].image);
        v.depth.as_ref().unwrap().0.clone()
    };
    let onnx = model("depth.onnx");

    // Metric depth, at the view's own size (the model takes any).
    assert_eq!(
        depth_of(depth_params(&onnx, Predicts::Depth, Units::Metric)),
        value
    );

    // DepthPro's canonical inverse depth: z = fx / (width * value); fx = 2 * width here.
    let canonical: Vec<f32> = value.iter().map(|&v| 2.0 / v).collect();
    assert_eq!(
        depth_of(depth_params(
            &onnx,
            Predicts::CanonicalInverseDepth,
            Units::Metric
        )),
        canonical
    );

    // Relative inverse depth: 1 / value, scaled so the (lower) median is 1.
    let inverse: Vec<f32> = value.iter().map(|&v| 1.0 / v).collect();
    let mut sorted = inverse.clone();
    sorted.sort_by(f32::total_cmp);
    let median = sorted[(sorted.len() - 1) / 2];
    let relative: Vec<f32> = inverse.iter().map(|&d| d / median).collect();
    let mut p = depth_params(&onnx, Predicts::InverseDepth, Units::Relative);
    assert_eq!(depth_of(p.clone()), relative);

    // Resized in and out: half size, each 2 x 2 block one model pixel.
    p.input.size = Some((4, 3));
    assert_eq!(depth_of(p.clone()), relative);

    // More threads, same bits.
    p.threads = 2;
    assert_eq!(depth_of(p), relative);
}

/// Asserts `e` is a `BadInput` naming `file` (exit 2 on the command line); its message.
fn blames(e: &StageError, file: &Path) -> String {
    assert!(
        matches!(e, StageError::BadInput { file: f, .. } if f == file),
        "{e}"
    );
    assert!(e.is_user_error());
    e.to_string()
}

#[test]
fn a_file_that_is_not_a_model_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("not_a_model.onnx");
    std::fs::write(&fake, "this is not protobuf\n").unwrap();
    let labels = table(dir.path(), [Some("wall"), None, None, None]);
    for e in [
        segment(
            &seg_params(&fake, &labels, Target::Arch),
            &view_set(SCENE, &[]),
        )
        .unwrap_err(),
        estimate(
            &depth_params(&fake, Predicts::Depth, Units::Metric),
            &view_set(SCENE, &[]),
        )
        .unwrap_err(),
    ] {
        let msg = blames(&e, &fake);
        assert!(
            msg.contains("not_a_model.onnx") && msg.contains("an ONNX model"),
            "{msg}"
        );
    }
}

#[test]
fn outputs_of_the_wrong_shape_name_the_model_and_the_shape_expected() {
    let dir = tempfile::tempdir().unwrap();
    // A depth model must give one value per pixel; the segmentation model gives four.
    let seg = model("seg_logits.onnx");
    let e = estimate(
        &depth_params(&seg, Predicts::Depth, Units::Metric),
        &view_set(SCENE, &[]),
    )
    .unwrap_err();
    let msg = blames(&e, &seg);
    assert!(
        msg.contains("[1, 1, H, W]") && msg.contains("[1, 4, 6, 8]"),
        "{msg}"
    );

    // Four logits against a table of five classes whose last is mapped.
    let labels = dir.path().join("five.ron");
    std::fs::write(
        &labels,
        r#"(model: "five", classes: [("a", None), ("b", None), ("c", None), ("d", None), ("e", Some("car"))])"#,
    )
    .unwrap();
    let e = segment(
        &seg_params(&seg, &labels, Target::Instances),
        &view_set(SCENE, &[]),
    )
    .unwrap_err();
    let msg = blames(&e, &seg);
    assert!(msg.contains("[1, 5, H, W]"), "{msg}");

    // A trailing ignored class may be missing from the model (Mapillary's "Unlabeled").
    std::fs::write(
        &labels,
        r#"(model: "five", classes: [("a", Some("car")), ("b", None), ("c", None), ("d", None), ("e", None)])"#,
    )
    .unwrap();
    segment(
        &seg_params(&seg, &labels, Target::Instances),
        &view_set(SCENE, &[]),
    )
    .unwrap();
}

/// Runs the logits model with the table at `labels`; the error must name the table.
fn table_error(labels: &Path, target: Target) -> String {
    let p = seg_params(&model("seg_logits.onnx"), labels, target);
    blames(&segment(&p, &view_set(SCENE, &[])).unwrap_err(), labels)
}

#[test]
fn a_table_naming_a_class_we_do_not_have_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let labels = table(dir.path(), [Some("wall"), Some("spaceship"), None, None]);
    let e = table_error(&labels, Target::Instances);
    assert!(e.contains("spaceship"), "{e}");

    // Instance classes are not materials.
    let labels = table(dir.path(), [Some("wall"), None, None, None]);
    table_error(&labels, Target::Material);

    // Not a table at all: the place is a line and column.
    std::fs::write(&labels, "(model: \"x\", classes: [(\"a\", Some(wall))])").unwrap();
    let e = table_error(&labels, Target::Instances);
    assert!(e.contains("line 1"), "{e}");
}

#[test]
fn the_shipped_label_tables_read_and_use_our_classes() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs/labels");
    for (name, n, vocabulary) in [
        (
            "cityscapes.ron",
            19,
            [ARCH_CLASSES, CLUTTER_CLASSES].concat(),
        ),
        (
            "mapillary_vistas.ron",
            66,
            [ARCH_CLASSES, CLUTTER_CLASSES].concat(),
        ),
        ("ade20k.ron", 150, [ARCH_CLASSES, CLUTTER_CLASSES].concat()),
        ("rmsnet.ron", 20, RMSNET_CLASSES.to_vec()),
        // The CMP SegFormer's 13 outputs: "unknown" and the 12 CMP classes.
        (
            "cmp_facade.ron",
            13,
            [ARCH_CLASSES, CLUTTER_CLASSES].concat(),
        ),
        (
            "sam3_prompts.ron",
            24,
            [ARCH_CLASSES, CLUTTER_CLASSES].concat(),
        ),
    ] {
        let t = LabelTable::read(&dir.join(name)).unwrap();
        assert_eq!(t.classes.len(), n, "{name}");
        for (theirs, ours) in &t.classes {
            if let Some(o) = ours {
                assert!(vocabulary.contains(&o.as_str()), "{name}: {theirs} -> {o}");
            }
        }
    }
}

/// The façade model's table gives the relief its openings and balconies, and the prompt table
/// every architectural and clutter class (drainpipes only come from prompting).
#[test]
fn the_facade_and_prompt_tables_reach_the_relief_classes() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs/labels");
    let ours = |name: &str| -> Vec<String> {
        LabelTable::read(&dir.join(name))
            .unwrap()
            .classes
            .into_iter()
            .filter_map(|(_, o)| o)
            .collect()
    };
    let cmp = ours("cmp_facade.ron");
    for class in ["wall", "window", "door", "balcony"] {
        assert!(cmp.iter().any(|c| c == class), "cmp_facade.ron: {class}");
    }
    let prompts = ours("sam3_prompts.ron");
    for class in ARCH_CLASSES.iter().chain(CLUTTER_CLASSES) {
        assert!(
            prompts.iter().any(|c| c == class),
            "sam3_prompts.ron: {class}"
        );
    }
}

#[test]
fn the_registry_lists_the_model_stages() {
    macro_rules! names {
        ($($s:ty),* $(,)?) => { vec![$(<$s as Stage>::KIND),*] };
    }
    let kinds: Vec<&str> = kodama_nodes::for_each_stage!(names);
    assert!(kinds.contains(&"SegmentViews") && kinds.contains(&"EstimateDepth"));
    assert!(kinds.contains(&"ReadViews"), "the main list is still there");
}

/// Run in a child process without ORT_DYLIB_PATH (ONNX Runtime loads once per process).
#[test]
fn without_ort_dylib_path_the_error_says_what_to_install() {
    const CHILD: &str = "KODAMA_ONNX_TEST_CHILD";
    let name = "without_ort_dylib_path_the_error_says_what_to_install";
    if std::env::var_os(CHILD).is_some() {
        let p = depth_params(&model("depth.onnx"), Predicts::Depth, Units::Metric);
        let e = estimate(&p, &view_set(SCENE, &[])).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("ORT_DYLIB_PATH is not set")
                && msg.contains("pip install onnxruntime")
                && msg.contains("export ORT_DYLIB_PATH="),
            "{msg}"
        );
        return;
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", name, "--test-threads=1", "--nocapture"])
        .env(CHILD, "1")
        .env_remove("ORT_DYLIB_PATH")
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && text.contains("1 passed"), "{text}");
}
