//! Spec strings: parsing, canonical names, exact counts, errors.

use megaray_gen::{GenError, GenSpec};

fn parse(s: &str) -> GenSpec {
    s.parse().unwrap_or_else(|e| panic!("{s}: {e}"))
}

fn error(s: &str) -> String {
    match s.parse::<GenSpec>() {
        Ok(spec) => panic!("{s} parsed as {spec:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn good_specs() {
    assert_eq!(parse("grid:1000"), GenSpec::Grid { n: 1000 });
    assert_eq!(parse(" Grid:7 "), GenSpec::Grid { n: 7 });
    assert_eq!(parse("sphereflake:4"), GenSpec::Sphereflake { levels: 4, bands: 12 });
    assert_eq!(parse("sphereflake:4:12"), GenSpec::Sphereflake { levels: 4, bands: 12 });
    assert_eq!(parse("sphereflake:2:5"), GenSpec::Sphereflake { levels: 2, bands: 5 });
    let plant = |tris, seed| GenSpec::Plant { tris, seed };
    assert_eq!(parse("plant:100M"), plant(100_000_000, 1));
    assert_eq!(parse("plant:2.5M"), plant(2_500_000, 1));
    assert_eq!(parse("plant:1G"), plant(1_000_000_000, 1));
    assert_eq!(parse("plant:1g"), plant(1_000_000_000, 1));
    assert_eq!(parse("plant:300k"), plant(300_000, 1));
    assert_eq!(parse("plant:300K"), plant(300_000, 1));
    assert_eq!(parse("plant:7m"), plant(7_000_000, 1));
    assert_eq!(parse("plant:5000"), plant(5000, 1));
    assert_eq!(parse("plant:0.1M"), plant(100_000, 1));
    assert_eq!(parse("plant:100M:7"), plant(100_000_000, 7));
}

#[test]
fn names_are_canonical_and_parse_back() {
    let cases = [
        ("grid:1000", "grid:1000"),
        ("sphereflake:4:12", "sphereflake:4"),
        ("sphereflake:3:8", "sphereflake:3:8"),
        ("plant:100M", "plant:100M"),
        ("plant:2.5M", "plant:2500k"),
        ("plant:1000000000", "plant:1G"),
        ("plant:12345", "plant:12345"),
        ("plant:300k:9", "plant:300k:9"),
    ];
    for (s, name) in cases {
        let spec = parse(s);
        assert_eq!(spec.name(), name);
        assert_eq!(spec.to_string(), name);
        assert_eq!(parse(name), spec);
    }
    assert_eq!(parse("plant:1M").with_seed(42).name(), "plant:1M:42");
    assert_eq!(parse("plant:1M:42").with_seed(1).name(), "plant:1M");
    assert_eq!(parse("grid:10").with_seed(42), GenSpec::Grid { n: 10 });
}

#[test]
fn bad_specs_say_what_is_wrong() {
    assert_eq!(error("plant:abc"), "`plant:abc`: not a triangle count");
    assert_eq!(error("cube:3"), "`cube:3`: unknown model (use grid:N, sphereflake:L[:S] or plant:T[:SEED])");
    assert!(error("").contains("unknown model"));
    assert!(error("grid").contains("expected grid:N"));
    assert!(error("grid:").contains("not a number of cells"));
    assert!(error("grid:abc").contains("not a number of cells"));
    assert!(error("grid:-5").contains("not a number of cells"));
    assert!(error("grid:1.5").contains("not a number of cells"));
    assert!(error("grid:0").contains("1 to 65534"));
    assert!(error("grid:65535").contains("1 to 65534"));
    assert!(error("grid:10:2").contains("expected grid:N"));
    assert!(error("sphereflake:11").contains("at most 10 levels"));
    assert!(error("sphereflake:x").contains("not a number of levels"));
    assert!(error("sphereflake:4:1").contains("2 to 1000 latitude bands"));
    assert!(error("sphereflake:4:b").contains("not a number of bands"));
    assert!(error("sphereflake:1:2:3").contains("expected sphereflake"));
    assert!(error("plant:").contains("not a triangle count"));
    assert!(error("plant:M").contains("not a triangle count"));
    assert!(error("plant:1.2.3M").contains("not a triangle count"));
    assert!(error("plant:10T").contains("not a triangle count"));
    assert!(error("plant:-1M").contains("not a triangle count"));
    assert!(error("plant:10").contains("1k to 100G"));
    assert!(error("plant:1000G").contains("1k to 100G"));
    assert!(error("plant:1M:x").contains("not a seed"));
    assert!(error("plant:1M:1:2").contains("expected plant"));
    assert!(matches!("plant:abc".parse::<GenSpec>(), Err(GenError::Spec { .. })));
}

#[test]
fn counts_without_generating() {
    assert_eq!(parse("grid:1").counts(), (4, 2));
    assert_eq!(parse("grid:1000").counts(), (1_002_001, 2_000_000));
    assert_eq!(parse("sphereflake:0:2").counts(), (6, 8));
    assert_eq!(parse("sphereflake:4").counts(), (7381 * 266, 3_897_168));
    // Cheap even for a huge plant: the layout only.
    let (v, t) = parse("plant:1G").counts();
    assert!(t.abs_diff(1_000_000_000) < 20_000_000, "{t}");
    assert!(v > t / 2 && v < t, "{v}");
}
