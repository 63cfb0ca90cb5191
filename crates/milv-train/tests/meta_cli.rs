//! `milv-train meta`, `eval` and `table` end to end on a small simulated dataset: every
//! variant trains from a pinned version, a run resumes, policies adapt one-shot in
//! milv-sim, and the errors users meet are clear.
#![allow(clippy::unwrap_used)]

mod common;

use common::{json, run, s};

use std::path::{Path, PathBuf};

use milv_data::{CommitMeta, Dataset};

/// A tiny A-CycleGAN checkpoint (2 steps), translated into the imagined table, scored
/// and curated; returns the checkpoint and the curated version (a later curation
/// replaces this one's weights, so policies pin the version).
fn translator(ds: &Path, out: &Path, decoupled: bool) -> (PathBuf, u64) {
    let mut args = vec![
        "cyclegan",
        s(ds),
        "--out",
        s(out),
        "--steps",
        "2",
        "--checkpoint-every",
        "2",
        "--tiny",
        "--size",
        "32",
        "--threads",
        "1",
        "--json",
    ];
    if decoupled {
        args.push("--decoupled");
    }
    let rep = json(&args);
    let ckpt = PathBuf::from(rep["checkpoint"].as_str().unwrap());
    json(&[
        "translate",
        s(ds),
        "--checkpoint",
        s(&ckpt),
        "--threads",
        "1",
        "--json",
    ]);
    let model = rep["model_id"].as_str().unwrap().to_string();
    let d = Dataset::open(ds).unwrap();
    let meta = || CommitMeta::for_this_process("milv-train-test", "score");
    milv_score::score_dataset(
        &d,
        None,
        &milv_score::RunOptions {
            source: milv_score::Source::Imagined,
            model_id: Some(model),
            episodes: None,
            domain: None,
            jobs: 1,
            partition: None,
            skip_bad: false,
        },
        meta(),
        &|_| {},
    )
    .unwrap();
    let cur = milv_score::curate(
        &d,
        &milv_score::CurateOptions {
            run_id: None,
            rule: milv_score::Rule::TopFraction(0.8),
            min_episode_fraction: 0.0,
        },
        meta(),
    )
    .unwrap();
    (ckpt, cur.version)
}

/// `eval RUN` with one trial per training task, as JSON.
fn eval_once_on_training_tasks(run: &Path) -> serde_json::Value {
    json(&[
        "eval",
        s(run),
        "--trials",
        "1",
        "--split",
        "train",
        "--threads",
        "1",
        "--json",
    ])
}

const TINY: [&str; 5] = ["--tiny", "--threads", "1", "--json", "--checkpoint-every"];

#[test]
fn every_variant_meta_trains_resumes_and_is_evaluated_one_shot() {
    let dir = tempfile::tempdir().unwrap();
    let fx = common::sim_dataset(dir.path(), 3, true);
    let (coupled, v_coupled) = translator(&fx.root, &dir.path().join("acg"), false);
    let (decoupled, v_decoupled) = translator(&fx.root, &dir.path().join("acg-dec"), true);
    let at = |v: u64| format!("{}@{v}", s(&fx.root));
    let (ds_coupled, ds_decoupled) = (at(v_coupled), at(v_decoupled));
    let mut reports = Vec::new();
    for variant in ["daml", "milv", "wstable", "feedimg", "degi"] {
        let out = dir.path().join(variant);
        let (tr, ds) = if variant == "degi" {
            (&decoupled, &ds_decoupled)
        } else {
            (&coupled, &ds_coupled)
        };
        let mut args = vec!["meta", ds, "--variant", variant, "--out", s(&out), "--steps", "3"];
        if variant != "daml" {
            args.extend(["--translator", s(tr)]);
        }
        args.extend(TINY);
        args.push("3");
        let rep = json(&args);
        assert_eq!(rep["step"], 3, "{variant}");
        assert!(rep["outer_first"].as_f64().unwrap().is_finite(), "{variant}");
        let losses = std::fs::read_to_string(out.join("losses.jsonl")).unwrap();
        assert_eq!(losses.lines().count(), 3);
        let ckpt = PathBuf::from(rep["checkpoint"].as_str().unwrap());
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(ckpt.join("policy.json")).unwrap()).unwrap();
        assert_eq!(meta["meta"]["variant"], variant);
        assert_eq!(meta["meta"]["second_order"], true);
        assert_eq!(meta["translator"].is_null(), variant == "daml");
        let input = if matches!(variant, "daml" | "feedimg") {
            "image"
        } else {
            "latent"
        };
        assert_eq!(meta["policy"]["input"], input);
        // One-shot evaluation: one trial of each of the 12 held-out shapes.
        let report = dir.path().join(format!("{variant}.json"));
        let ev = json(&[
            "eval",
            s(&out),
            "--trials",
            "1",
            "--threads",
            "1",
            "--json",
            "-o",
            s(&report),
        ]);
        assert_eq!(ev["family"], "drawing");
        assert_eq!(ev["trials"], 12);
        // The inner step's effect on the evaluated instances: the imitation loss of the
        // expert's rollouts before and after adapting, which one step must change.
        let (pre, post) = (
            ev["loss_pre"].as_f64().unwrap(),
            ev["loss_post"].as_f64().unwrap(),
        );
        assert!(pre > 0.0 && post > 0.0 && pre != post, "{variant}: {pre} {post}");
        assert_eq!(ev["per_task"].as_array().unwrap().len(), 12);
        let lo = ev["wilson95"][0].as_f64().unwrap();
        let rate = ev["rate"].as_f64().unwrap();
        assert!(lo <= rate && rate <= ev["wilson95"][1].as_f64().unwrap());
        reports.push(report);
    }
    // Resume continues the same run.
    let out = dir.path().join("milv");
    let mut args = vec![
        "meta",
        &ds_coupled,
        "--variant",
        "milv",
        "--translator",
        s(&coupled),
    ];
    args.extend(["--out", s(&out), "--steps", "5", "--resume"]);
    args.extend(TINY);
    args.push("3");
    let rep = json(&args);
    assert_eq!(
        (rep["step"].as_u64(), rep["steps_run"].as_u64()),
        (Some(5), Some(2))
    );
    // Without --resume an existing run is refused.
    let (code, _, err) = run(&[
        "meta",
        s(&fx.root),
        "--variant",
        "daml",
        "--out",
        s(&dir.path().join("daml")),
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("--resume"), "{err}");

    // Packs evaluate as their checkpoints did, from wherever they are moved to: DAML's
    // exactly (f32), MILV's with the translator in f16 within rounding.
    for (variant, half) in [("daml", false), ("milv", true)] {
        let packed = dir.path().join("packs").join(variant);
        // The step the reports above evaluated (milv has resumed past it since).
        let trained = dir.path().join(variant).join("checkpoints/step-00000003");
        let mut args = vec!["pack", s(&trained), "--out", s(&packed), "--json"];
        if half {
            args.push("--half");
        }
        let rep = json(&args);
        assert_eq!(rep["variant"], variant);
        assert_eq!(rep["half_translator"], half);
        assert_eq!(packed.join("translator").is_dir(), variant == "milv");
        assert!(!packed.join("state.safetensors").exists());
        let moved = dir.path().join(format!("moved-{variant}"));
        std::fs::rename(&packed, &moved).unwrap();
        let ev = json(&["eval", s(&moved), "--trials", "1", "--threads", "1", "--json"]);
        let before: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join(format!("{variant}.json"))).unwrap())
                .unwrap();
        assert_eq!(ev["trials"], before["trials"]);
        for k in ["loss_pre", "loss_post"] {
            let (a, b) = (ev[k].as_f64().unwrap(), before[k].as_f64().unwrap());
            if half {
                assert!((a - b).abs() <= 0.02 * b, "{variant} {k}: {a} vs {b}");
            } else {
                assert_eq!(a, b, "{variant} {k}");
            }
        }
        if !half {
            assert_eq!(ev["successes"], before["successes"]);
        }
    }
    // A pack whose networks were edited is refused, naming the pack.
    let g = dir.path().join("moved-milv/translator/G.safetensors");
    let mut bytes = std::fs::read(&g).unwrap();
    let n = bytes.len();
    bytes[n - 1] ^= 0x55;
    std::fs::write(&g, bytes).unwrap();
    let (code, _, err) = run(&["eval", s(&dir.path().join("moved-milv")), "--trials", "1"]);
    assert_ne!(code, 0);
    assert!(err.contains("corrupt") && err.contains("moved-milv"), "{err}");
    // Policies of one A-CycleGAN share one packed translator (`--translators`), and the
    // shelf moves as a whole.
    let shelf = dir.path().join("shelf");
    for variant in ["wstable", "feedimg"] {
        let trained = dir.path().join(variant);
        let (out, shared) = (shelf.join(variant), shelf.join("translators"));
        let rep = json(&[
            "pack",
            s(&trained),
            "--out",
            s(&out),
            "--half",
            "--translators",
            s(&shared),
            "--json",
        ]);
        assert!(!out.join("translator").exists());
        assert!(rep["translator_dir"].as_str().unwrap().contains("translators"));
    }
    assert_eq!(std::fs::read_dir(shelf.join("translators")).unwrap().count(), 1);
    let moved = dir.path().join("shelf-moved");
    std::fs::rename(&shelf, &moved).unwrap();
    for variant in ["wstable", "feedimg"] {
        let ev = json(&[
            "eval",
            s(&moved.join(variant)),
            "--trials",
            "1",
            "--threads",
            "1",
            "--json",
        ]);
        assert_eq!(ev["trials"], 12, "{variant}");
    }

    let mut args = vec!["table"];
    args.extend(reports.iter().map(|p| s(p)));
    let (code, md, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    for label in ["DAML", "DeGI", "FeedImg", "WStable", "MILV"] {
        assert!(md.contains(&format!("| {label} |")), "{md}");
    }
    assert!(md.contains("/12; 95 % CI"), "{md}");
}

#[test]
fn wrong_translators_and_missing_inputs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let fx = common::sim_dataset(dir.path(), 2, true);
    let (coupled, _) = translator(&fx.root, &dir.path().join("acg"), false);
    let base = |variant: &'static str, out: &str| -> Vec<String> {
        let mut v: Vec<String> = ["meta", s(&fx.root), "--variant", variant, "--out"]
            .iter()
            .map(|x| x.to_string())
            .collect();
        v.push(dir.path().join(out).display().to_string());
        v.extend(["--tiny", "--steps", "1"].map(String::from));
        v
    };
    let call = |args: &[String]| run(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let (code, _, err) = call(&base("milv", "a"));
    assert_ne!(code, 0);
    assert!(err.contains("--translator"), "{err}");
    let mut degi = base("degi", "b");
    degi.extend(["--translator".into(), s(&coupled).into()]);
    let (code, _, err) = call(&degi);
    assert_ne!(code, 0);
    assert!(err.contains("decoupled"), "{err}");
    // A 2-step translator's imagined actions do not follow the true ones: with ground
    // truth, training on them is refused unless asked for.
    let mut weak = base("milv", "c");
    weak.extend([
        "--translator".into(),
        s(&coupled).into(),
        "--truth".into(),
        s(&fx.truth).into(),
    ]);
    let (code, _, err) = call(&weak);
    assert_ne!(code, 0);
    assert!(
        err.contains("refusing to train milv") && err.contains("correlate"),
        "{err}"
    );
    assert!(err.contains("--allow-weak-translator"), "{err}");
    weak.push("--allow-weak-translator".into());
    let (code, _, err) = call(&weak);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("imagined vs true robot actions") && err.contains("warning"),
        "{err}"
    );
    // --true-actions (the ladder's R6): the same imagined inputs, the true robot actions
    // as targets, so no refusal, targets that vary as the robot's do, and rows that say so.
    let spread = |err: &str| -> Vec<f64> {
        let line = err
            .lines()
            .find(|l| l.contains("standard deviation (cm)"))
            .unwrap_or_else(|| panic!("{err}"));
        let inside = &line[line.find('[').unwrap() + 1..line.find(']').unwrap()];
        inside.split(", ").map(|x| x.parse().unwrap()).collect()
    };
    let imagined = spread(&err);
    let truth_run = dir.path().join("r6");
    let mut r6 = base("milv", "r6");
    r6.extend([
        "--translator".into(),
        s(&coupled).into(),
        "--truth".into(),
        s(&fx.truth).into(),
        "--true-actions".into(),
        "--checkpoint-every".into(),
        "1".into(),
    ]);
    let (code, _, err) = call(&r6);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("--true-actions") && !err.contains("refusing"),
        "{err}"
    );
    let truth = spread(&err);
    assert!(
        truth.iter().zip(&imagined).all(|(t, i)| *t > 0.1 && t != i),
        "true {truth:?} vs imagined {imagined:?}"
    );
    let ev = eval_once_on_training_tasks(&truth_run);
    assert_eq!(ev["true_actions"], true, "{ev}");
    // A human demo the truth file does not pair is an error naming the file and the demo.
    let partial = dir.path().join("partial_truth.jsonl");
    let first = std::fs::read_to_string(&fx.truth).unwrap();
    std::fs::write(&partial, first.lines().next().unwrap()).unwrap();
    let mut r6c = base("milv", "r6c");
    r6c.extend([
        "--translator".into(),
        s(&coupled).into(),
        "--truth".into(),
        s(&partial).into(),
        "--true-actions".into(),
    ]);
    let (code, _, err) = call(&r6c);
    assert_ne!(code, 0);
    assert!(
        err.contains("partial_truth.jsonl") && err.contains("has no robot demo"),
        "{err}"
    );
    let (code, _, err) = call(
        &base("milv", "r6b")
            .into_iter()
            .chain(["--true-actions".into()])
            .collect::<Vec<_>>(),
    );
    assert_ne!(code, 0);
    assert!(err.contains("--truth"), "{err}");
    let (code, _, err) = run(&["eval", s(&dir.path().join("nothing"))]);
    assert_ne!(code, 0);
    assert!(err.contains("neither a policy checkpoint"), "{err}");
    let (code, _, err) = run(&["meta", s(&fx.root), "--variant", "dagger", "--out", "x"]);
    assert_ne!(code, 0);
    assert!(err.contains("unknown variant"), "{err}");
}

/// DAML's inner-loop flags, the pre-adaptation loss, `eval --split/--demo` and the meta
/// loss chart, through the real binary.
#[test]
fn daml_inner_loop_flags_visibility_and_evaluation_options() {
    let dir = tempfile::tempdir().unwrap();
    let fx = common::sim_dataset(dir.path(), 3, true);
    let ds = s(&fx.root);
    let runs = [
        ("daml-defaults", vec![]),
        (
            "daml-plain",
            vec![
                "--loss-multiplier",
                "1",
                "--inner-clip",
                "0",
                "--bias-dim",
                "0",
                "--no-layer-norm",
                "--fixed-temperature",
                "--hidden",
                "5",
                // Behaviour cloning (the ladder's R0/R1): no inner step at all.
                "--alpha",
                "0",
            ],
        ),
    ];
    for (name, flags) in &runs {
        let out = dir.path().join(name);
        let mut args = vec!["meta", ds, "--variant", "daml", "--out", s(&out), "--steps", "4"];
        args.extend(flags.iter().copied());
        args.extend(TINY);
        args.push("4");
        let rep = json(&args);
        assert!(
            rep["outer_pre_last"].as_f64().unwrap().is_finite(),
            "{name}: {rep}"
        );
        let ckpt = PathBuf::from(rep["checkpoint"].as_str().unwrap());
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(ckpt.join("policy.json")).unwrap()).unwrap();
        let p = &meta["policy"];
        if flags.is_empty() {
            assert_eq!(
                (p["loss_multiplier"].as_f64(), p["inner_clip"].as_f64()),
                (Some(50.0), Some(10.0))
            );
            assert_eq!(p["layer_norm"], true);
            assert_eq!(p["learned_temperature"], true);
            assert!(p["bias_dim"].as_i64().unwrap() > 0);
        } else {
            assert_eq!(
                (p["loss_multiplier"].as_f64(), p["inner_clip"].as_f64()),
                (Some(1.0), Some(0.0))
            );
            assert_eq!((p["bias_dim"].as_i64(), p["hidden"].as_i64()), (Some(0), Some(5)));
            assert_eq!(p["layer_norm"], false);
            assert_eq!(p["learned_temperature"], false);
        }
        // Every step logs the outer loss after and before adaptation.
        let losses = std::fs::read_to_string(out.join("losses.jsonl")).unwrap();
        for line in losses.lines() {
            let v: serde_json::Value = serde_json::from_str(line).unwrap();
            assert!(
                v["outer"].as_f64().unwrap() >= 0.0 && v["outer_pre"].as_f64().unwrap() > 0.0,
                "{v}"
            );
            if !flags.is_empty() {
                let (post, pre) = (v["outer"].as_f64().unwrap(), v["outer_pre"].as_f64().unwrap());
                assert!((post - pre).abs() <= 1e-5 * pre, "α = 0 leaves θ as it is: {v}");
            }
        }
    }
    let out = dir.path().join("daml-defaults");
    for (split, demo, tasks) in [("train", "own", 11), ("test", "swap", 12)] {
        let ev = json(&[
            "eval",
            s(&out),
            "--trials",
            "1",
            "--split",
            split,
            "--demo",
            demo,
            "--threads",
            "1",
            "--json",
        ]);
        assert_eq!(
            (ev["split"].as_str(), ev["demo"].as_str()),
            (Some(split), Some(demo))
        );
        assert_eq!(ev["per_task"].as_array().unwrap().len(), tasks, "{split}");
    }
    // --instances: the fixture's own instances (what the policy trained on), each from two
    // other start positions; a file of the wrong family is refused, naming it.
    let inst = dir.path().join("instances.jsonl");
    let rows: String = milv_sim::shapes::training_shapes()[..3]
        .iter()
        .enumerate()
        .map(|(i, sh)| {
            let task = milv_sim::env::Task::Drawing { shape: sh.clone() };
            serde_json::json!({"index": i, "task": task}).to_string() + "\n"
        })
        .collect();
    std::fs::write(&inst, rows).unwrap();
    let ev = json(&[
        "eval",
        s(&out),
        "--instances",
        s(&inst),
        "--trials",
        "2",
        "--threads",
        "1",
        "--json",
    ]);
    assert_eq!(ev["instances"].as_str(), Some(s(&inst)));
    assert_eq!(
        ev["frames"], "h264",
        "evaluation frames pass the training codec by default"
    );
    assert_eq!(
        (ev["trials"].as_u64(), ev["per_task"].as_array().unwrap().len()),
        (Some(6), 3)
    );
    assert!(ev["loss_pre"].as_f64().unwrap() > 0.0, "{ev}");
    let (code, _, err) = run(&[
        "eval",
        s(&out),
        "--instances",
        s(&inst),
        "--family",
        "pushing",
        "--trials",
        "1",
    ]);
    assert_eq!(code, 1);
    assert!(
        err.contains("instances.jsonl line 1: a drawing instance"),
        "{err}"
    );
    let charts = dir.path().join("charts");
    let (code, stdout, err) = run(&[
        "report",
        s(&out),
        s(&dir.path().join("daml-plain")),
        "-o",
        s(&charts),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("meta_losses.png"), "{stdout}");
    assert!(std::fs::metadata(charts.join("meta_losses.png")).unwrap().len() > 1000);
    // DAML robot → robot: the inner step watches another robot demo; eval shows robot demos.
    let robot = dir.path().join("daml-robot");
    let mut args = vec![
        "meta",
        ds,
        "--variant",
        "daml",
        "--inner",
        "robot",
        "--out",
        s(&robot),
        "--steps",
        "2",
    ];
    args.extend(TINY);
    args.push("2");
    json(&args);
    let ev = json(&["eval", s(&robot), "--trials", "1", "--threads", "1", "--json"]);
    assert_eq!(ev["demo_domain"], "robot");
    let (code, _, err) = run(&[
        "meta",
        ds,
        "--variant",
        "daml",
        "--inner",
        "robot",
        "--out",
        s(&robot),
        "--resume",
        "--steps",
        "3",
        "--tiny",
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(&[
        "meta",
        ds,
        "--variant",
        "daml",
        "--out",
        s(&robot),
        "--resume",
        "--steps",
        "4",
        "--tiny",
    ]);
    assert_eq!(code, 1, "resuming a robot → robot run as human → robot must fail");
    assert!(err.contains("the data changed"), "{err}");
    // --state: the robot's state as an extra input, standardised, recorded in the policy
    // and in the eval report; resuming without it is refused.
    let st = dir.path().join("daml-state");
    let mut args = vec![
        "meta",
        ds,
        "--variant",
        "daml",
        "--state",
        "--out",
        s(&st),
        "--steps",
        "2",
    ];
    args.extend(TINY);
    args.push("2");
    let rep = json(&args);
    let ckpt = PathBuf::from(rep["checkpoint"].as_str().unwrap());
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ckpt.join("policy.json")).unwrap()).unwrap();
    assert_eq!(meta["policy"]["state_dim"], 2);
    let norm = meta["policy"]["state_norm"].as_array().unwrap();
    assert_eq!(norm.len(), 2);
    assert!(norm.iter().all(|m| m[1].as_f64().unwrap() > 0.1), "{norm:?}");
    let ev = eval_once_on_training_tasks(&st);
    assert_eq!(ev["state_input"], true);
    assert!(ev["loss_pre"].as_f64().unwrap() > 0.0);
    let (code, _, err) = run(&[
        "meta",
        ds,
        "--variant",
        "daml",
        "--out",
        s(&st),
        "--resume",
        "--steps",
        "3",
        "--tiny",
    ]);
    assert_eq!(code, 1, "resuming a --state run without --state must fail");
    assert!(err.contains("the data changed"), "{err}");
    let (code, _, err) = run(&[
        "meta",
        ds,
        "--variant",
        "daml",
        "--out",
        s(&dir.path().join("bad")),
        "--loss-multiplier",
        "0",
        "--tiny",
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("--loss-multiplier must be positive"), "{err}");
}

/// The packed policies of the small tables (`samples/policies/`, RESULTS.md) still load
/// and evaluate with this build: every pack's files are read, and one through its
/// shared f16 translator runs a one-trial evaluation.
#[test]
fn the_committed_policies_load_and_evaluate() {
    let shelf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../samples/policies");
    let mut packs = 0;
    for e in std::fs::read_dir(&shelf).unwrap() {
        let p = e.unwrap().path();
        if !p.join("policy.json").is_file() {
            continue;
        }
        let (_, meta) = milv_train::meta::train::read_meta(&p).unwrap();
        if let Some(t) = &meta.translator {
            let (_, id) = milv_train::gan::checkpoint::load_translation(&t.checkpoint, tch::Device::Cpu)
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            assert_eq!(id, t.model_id, "{}", p.display());
        }
        packs += 1;
    }
    assert_eq!(packs, 10, "five methods × two families");
    let ev = json(&[
        "eval",
        s(&shelf.join("pushing-milv")),
        "--trials",
        "1",
        "--seeds",
        "0",
        "--threads",
        "2",
        "--json",
    ]);
    assert_eq!(
        (ev["family"].as_str(), ev["trials"].as_u64()),
        (Some("pushing"), Some(8))
    );
    assert!(ev["loss_pre"].as_f64().unwrap().is_finite());
}
