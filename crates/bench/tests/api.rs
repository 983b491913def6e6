//! The harness's options, sources and output lines (small scenes, no timing assertions).

use megaray_base::NoProgress;
use megaray_bench::{parse_threads, run, BenchError, BenchOptions, Event, Kind, Loaded, Record, Source, View};

const TRACE_KEYS: [&str; 16] = [
    "peer",
    "scene",
    "tris",
    "kind",
    "threads",
    "width",
    "height",
    "rays",
    "mrays_s",
    "mrays_s_best",
    "ms_median",
    "cpu_util",
    "reps",
    "iters",
    "hits",
    "sum_t",
];
const BUILD_KEYS: [&str; 10] =
    ["peer", "scene", "tris", "kind", "threads", "build_ms", "build_ms_best", "mtris_s", "cpu_util", "reps"];

fn quick(kinds: &[Kind], threads: &[usize]) -> BenchOptions {
    BenchOptions {
        kinds: kinds.to_vec(),
        threads: threads.to_vec(),
        width: 64,
        height: 48,
        reps: 1,
        min_ms: 0.0,
        ..BenchOptions::default()
    }
}

fn events(loaded: &Loaded, opts: &BenchOptions) -> Result<(Vec<Record>, Vec<String>), BenchError> {
    let (mut lines, mut info) = (Vec::new(), Vec::new());
    run(loaded, opts, &NoProgress, &mut |e| match e {
        Event::Line(r) => lines.push(r),
        Event::Info(m) => info.push(m),
    })?;
    Ok((lines, info))
}

/// The keys of a flat JSON object line, in order, checked to be exactly `keys`.
fn assert_keys(line: &str, keys: &[&str]) {
    let v: serde_json::Value = serde_json::from_str(line).unwrap_or_else(|e| panic!("not JSON: {e}: {line}"));
    let obj = v.as_object().expect("an object");
    assert_eq!(obj.len(), keys.len(), "{line}");
    let mut at = 0;
    for k in keys {
        assert!(obj.contains_key(*k), "key {k} missing: {line}");
        let pos = line.find(&format!("\"{k}\":")).unwrap();
        assert!(pos >= at, "key {k} out of order: {line}");
        at = pos;
        assert!(!obj[*k].is_null(), "key {k} is null: {line}");
    }
    assert_eq!(obj["peer"], "megaray");
}

#[test]
fn json_lines_have_every_key_in_the_peers_order() {
    let loaded = Loaded::open(&Source::parse("grid:20").unwrap(), &NoProgress).unwrap();
    assert_eq!(loaded.name, "grid:20");
    let opts = quick(&Kind::ALL, &[1, 2]);
    let (lines, info) = events(&loaded, &opts).unwrap();
    assert_eq!(lines.len(), Kind::ALL.len() * 2);
    assert!(info.iter().any(|m| m.starts_with("primary hits ")), "{info:?}");
    // builds first (as the peer: high, then medium quality, at each thread count), then the
    // tracing kinds thread count by thread count
    let builds: Vec<(Kind, usize)> = lines
        .iter()
        .take(4)
        .map(|r| match r {
            Record::Build(b) => (b.kind, b.threads),
            Record::Trace(t) => panic!("a trace line ({}) before the builds", t.kind),
        })
        .collect();
    assert_eq!(builds, [(Kind::BuildHigh, 1), (Kind::Build, 1), (Kind::BuildHigh, 2), (Kind::Build, 2)]);
    assert!(matches!(&lines[0], Record::Build(b) if b.tris == 800 && b.reps == 1));
    for r in &lines {
        let json = r.json();
        assert!(!json.contains('\n'));
        match r {
            Record::Trace(t) => {
                assert_keys(&json, &TRACE_KEYS);
                assert_eq!((t.width, t.height, t.scene.as_str(), t.tris), (64, 48, "grid:20", 800));
                assert!(t.mrays_s > 0.0 && t.iters >= 1 && t.reps == 1);
                let v: serde_json::Value = serde_json::from_str(&json).unwrap();
                assert_eq!(v["kind"], t.kind.name());
                assert_eq!(v["hits"], t.hits);
            }
            Record::Build(b) => {
                assert_keys(&json, &BUILD_KEYS);
                let v: serde_json::Value = serde_json::from_str(&json).unwrap();
                assert_eq!(v["kind"], b.kind.name());
                assert!(b.build_ms > 0.0 && b.mtris_s > 0.0);
            }
        }
        assert!(!r.table_row().is_empty());
    }
    let p1: Vec<_> = lines
        .iter()
        .filter_map(|r| match r {
            Record::Trace(t) if matches!(t.kind, Kind::Primary1 | Kind::Primary8 | Kind::Primary16) => Some(t),
            _ => None,
        })
        .collect();
    assert_eq!(p1.len(), 6);
    assert!(p1[0].hits > 0, "the grid fills part of the image");
    for t in &p1 {
        assert_eq!(t.hits, p1[0].hits, "{}: every packet size hits the same", t.kind);
        assert!((t.sum_t - p1[0].sum_t).abs() <= 1e-9 * p1[0].sum_t);
    }
}

#[test]
fn unknown_kinds_and_bad_thread_counts_are_errors() {
    let e = Kind::parse_list("primary_1,bogus").unwrap_err().to_string();
    assert!(e.contains("bogus") && e.contains("primary_16"), "{e}");
    assert!(Kind::parse_list("").is_err());
    assert_eq!(Kind::parse_list(" build,primary_1,,build").unwrap(), vec![Kind::Build, Kind::Primary1]);
    assert_eq!(Kind::parse_list(Kind::DEFAULT).unwrap().len(), 6);
    assert_eq!(Kind::parse_list("build_high").unwrap(), vec![Kind::BuildHigh]);
    for bad in ["0", "x", "", "1,,-2", "2000"] {
        assert!(parse_threads(bad).is_err(), "--threads {bad}");
    }
    assert_eq!(parse_threads("1,2").unwrap(), vec![1, 2]);

    let loaded = Loaded::open(&Source::parse("grid:4").unwrap(), &NoProgress).unwrap();
    for opts in [
        BenchOptions { reps: 0, ..quick(&[Kind::Primary1], &[1]) },
        BenchOptions { min_ms: -1.0, ..quick(&[Kind::Primary1], &[1]) },
        quick(&[Kind::Primary1], &[0]),
        quick(&[], &[1]),
    ] {
        assert!(matches!(events(&loaded, &opts), Err(BenchError::Option(_))));
    }
}

#[test]
fn scene_arguments() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.obj");
    let e = Source::parse(missing.to_str().unwrap()).unwrap_err();
    assert!(matches!(e, BenchError::NoSuchScene(_)), "{e}");
    let txt = dir.path().join("notes.txt");
    std::fs::write(&txt, "hello").unwrap();
    assert!(matches!(Source::parse(txt.to_str().unwrap()), Err(BenchError::UnknownType(_))));
    assert!(matches!(Source::parse("grid:abc"), Err(BenchError::Gen(_))));
    assert!(matches!(Source::parse("nonsense"), Err(BenchError::NoSuchScene(_))));
    let s = Source::parse("sphereflake:1").unwrap();
    assert_eq!(s.name(), "sphereflake:1");

    // A .mray file is opened as it is; its triangles come back from its tiles.
    let ply = dir.path().join("g.ply");
    megaray_gen::write_ply(&"grid:30".parse().unwrap(), &ply, &NoProgress).unwrap();
    let mray = dir.path().join("g.mray");
    let bopts = megaray_build::BuildOptions { build_mem: 256 << 20, threads: 2, ..Default::default() };
    megaray_build::build_scene(&[ply], &mray, &bopts, &NoProgress).unwrap();
    let src = Source::parse(mray.to_str().unwrap()).unwrap();
    assert_eq!(src, Source::Scene(mray.clone()));
    let loaded = Loaded::open(&src, &NoProgress).unwrap();
    assert_eq!(loaded.name, "g.mray");
    assert_eq!(loaded.triangles(&NoProgress).unwrap().len(), 1800);

    // --name overrides the name; the close camera appends @close (once).
    let opts = BenchOptions { view: View::Close, ..quick(&[Kind::Build, Kind::Primary1], &[1]) };
    assert_eq!(opts.scene_name(&loaded), "g.mray@close");
    let named = BenchOptions { name: Some("x@close".into()), ..opts.clone() };
    assert_eq!(named.scene_name(&loaded), "x@close");
    let (lines, _) = events(&loaded, &opts).unwrap();
    assert_eq!(lines.len(), 2);
    for r in lines {
        let v: serde_json::Value = serde_json::from_str(&r.json()).unwrap();
        assert_eq!((v["scene"].as_str(), v["tris"].as_u64()), (Some("g.mray@close"), Some(1800)));
    }
}
