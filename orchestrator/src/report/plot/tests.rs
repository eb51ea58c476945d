use super::*;
use crate::evaluation::compare::{compare, CompareOptions, FailingWindow};
use crate::evaluation::frf::{comparison_responses, welch_h1, FRF_SEGMENT};
use crate::record::Signal;
use quick_xml::events::Event;
use std::f64::consts::PI;

const DT: f64 = 1.0 / 51.2;

/// Uniform in [-1, 1), reproducible (xorshift64*).
fn noise(seed: u64, n: usize) -> Vec<f64> {
    let mut state = seed.max(1);
    (0..n)
        .map(|_| {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            let bits = state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
            2.0 * (bits as f64 / (1u64 << 53) as f64) - 1.0
        })
        .collect()
}

/// The paper rig's channels, acc1..acc3.
fn accs() -> Vec<Channel> {
    (1..=3)
        .map(|f| Channel::parse(&format!("acc{f}")).expect("a channel"))
        .collect()
}

/// `values` as the force column.
fn force_signal(values: Vec<f64>) -> Signal {
    Signal {
        channel: Channel::Excitation(::structure::channel::ExcitationKind::Force),
        unit: ::structure::channel::Unit::Newton,
        values,
    }
}

/// 1024 samples, two failing windows: floor 3 alone, then floors 1 and 2.
fn synthetic() -> (Comparison, Signal) {
    let n = 1024;
    let time: Vec<f64> = (0..n).map(|k| k as f64 * DT).collect();
    let force = force_signal(noise(7, n));
    let predicted: Vec<Vec<f64>> = [1.0, 1.6, 2.0]
        .map(|gain| {
            time.iter()
                .map(|t| gain * (2.0 * PI * 3.0 * t).sin())
                .collect::<Vec<_>>()
        })
        .to_vec();
    let mut measured = predicted.clone();
    for (floor, values) in measured.iter_mut().enumerate() {
        for (v, e) in values.iter_mut().zip(noise(11 + floor as u64, n)) {
            *v += 0.05 * e;
        }
    }
    let failing_windows = vec![
        FailingWindow {
            start: 5.0,
            end: 5.4,
            channels: vec!["acc3".into()],
            floors: vec![3],
            nmse: vec![0.1, 0.1, 150.0],
        },
        FailingWindow {
            start: 12.0,
            end: 12.6,
            channels: vec!["acc1".into(), "acc2".into()],
            floors: vec![1, 2],
            nmse: vec![90.0, 60.0, 0.1],
        },
    ];
    let c = Comparison {
        time,
        channels: accs(),
        measured,
        predicted,
        noise_sd: vec![0.03; 3],
        band_sd: None,
        first: 103,
        nmse: vec![0.26, 2.44, 2.94],
        failing_windows,
        windows_below_tolerance: 0,
        tolerance: 0.0,
    };
    (c, force)
}

struct Svg {
    texts: String,
    /// (fill, opacity) of every <rect>.
    rects: Vec<(String, String)>,
}

/// Parses the whole file (failing on malformed XML), checks the root is <svg>, and collects
/// the text and the rectangles.
fn parse_svg(path: &Path) -> Svg {
    let source = std::fs::read_to_string(path).expect("the SVG is readable");
    let mut reader = quick_xml::Reader::from_str(&source);
    let mut svg = Svg {
        texts: String::new(),
        rects: Vec::new(),
    };
    let mut root = None;
    loop {
        match reader.read_event().unwrap_or_else(|e| {
            panic!(
                "{}: malformed at {}: {e}",
                path.display(),
                reader.buffer_position()
            )
        }) {
            Event::Eof => break,
            Event::Start(e) | Event::Empty(e) => {
                let name = String::from_utf8_lossy(e.name().as_ref()).into_owned();
                root.get_or_insert_with(|| name.clone());
                if name == "rect" {
                    let attr = |key: &str| {
                        e.try_get_attribute(key)
                            .ok()
                            .flatten()
                            .map(|a| String::from_utf8_lossy(&a.value).into_owned())
                            .unwrap_or_default()
                    };
                    svg.rects.push((attr("fill"), attr("opacity")));
                }
            }
            Event::Text(t) => {
                svg.texts += &t.unescape().expect("text unescapes");
                svg.texts.push('\n');
            }
            _ => {}
        }
    }
    assert_eq!(root.as_deref(), Some("svg"));
    svg
}

#[test]
fn time_view_is_well_formed_with_title_captions_and_one_span_per_window_and_panel() {
    let (c, force) = synthetic();
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("comparison.svg");
    plot_comparison(&c, &force.channel, None, "dataset 2 <linear model>", &path).expect("plots");

    let svg = parse_svg(&path);
    assert!(
        svg.texts.contains("dataset 2 <linear model>"),
        "{}",
        svg.texts
    );
    assert!(svg.texts.contains("acc1 — NMSE 0.26 %"), "{}", svg.texts);
    assert!(
        svg.texts
            .contains("acc3 — NMSE 2.94 % — out of band in 1 window"),
        "{}",
        svg.texts
    );
    assert!(svg.texts.contains("time (s)") && svg.texts.contains("acceleration (m/s²)"));

    // Each window is one rectangle in each of the three panels: strong on the floors that
    // left the band (3, then 1 and 2), faint on the others. The key draws its swatches as
    // polygons, so these are all the red rectangles there are.
    let failing = format!("#{:02X}{:02X}{:02X}", FAILING.0, FAILING.1, FAILING.2);
    let red: Vec<&String> = svg
        .rects
        .iter()
        .filter(|(fill, _)| *fill == failing)
        .map(|(_, opacity)| opacity)
        .collect();
    assert_eq!(red.len(), 3 * c.failing_windows.len(), "{red:?}");
    let strong = red
        .iter()
        .filter(|o| o.parse::<f64>().ok() == Some(FAILING_OPACITY))
        .count();
    let floors_out: usize = c.failing_windows.iter().map(|w| w.floors.len()).sum();
    assert_eq!(strong, floors_out);
    // The transient is greyed once per panel.
    let grey = format!("#{:02X}{:02X}{:02X}", TRANSIENT.0, TRANSIENT.1, TRANSIENT.2);
    assert_eq!(
        svg.rects.iter().filter(|(fill, _)| *fill == grey).count(),
        3
    );

    // Only the plot is left in the directory: no temporary file, no frequency view.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .expect("lists")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("comparison.svg")]);
}

#[test]
fn frequency_view_is_written_beside_the_time_view() {
    let (c, force) = synthetic();
    let dir = tempfile::tempdir().expect("temp dir");
    let responses = comparison_responses(&c, &force).expect("estimates");
    plot_comparison(
        &c,
        &force.channel,
        Some(&responses),
        "dataset 2",
        &dir.path().join("d2.svg"),
    )
    .expect("plots");
    let svg = parse_svg(&dir.path().join("d2-frf.svg"));
    for expected in ["dataset 2", "acc1", "acc3", "frequency (Hz)", "H1 estimate"] {
        assert!(
            svg.texts.contains(expected),
            "{expected} missing from {}",
            svg.texts
        );
    }
    assert!(dir.path().join("d2.svg").exists());
}

#[test]
fn only_svg_is_accepted_and_the_error_names_the_path() {
    let (c, force) = synthetic();
    let dir = tempfile::tempdir().expect("temp dir");
    for name in ["comparison.png", "comparison"] {
        let path = dir.path().join(name);
        let err = plot_comparison(&c, &force.channel, None, "t", &path).expect_err("refused");
        assert!(matches!(err, ReportError::UnsupportedFormat { .. }));
        assert_eq!(
            err.to_string(),
            format!("only .svg is supported: {}", path.display())
        );
        assert!(!path.exists());
    }
}

#[test]
fn bad_input_is_refused_before_anything_is_written() {
    let (c, force) = synthetic();
    let short = force_signal(force.values[..100].to_vec());
    // The frequency view is computed (`comparison_responses`) before anything is drawn or
    // written, and refuses the short excitation.
    let err = comparison_responses(&c, &short).expect_err("refused");
    assert!(
        err.contains("100 force samples for 1024 time samples"),
        "{err}"
    );
}

#[test]
fn h1_of_a_pure_gain_is_6_02_db_at_every_frequency() {
    let force = noise(3, 1024);
    let response: Vec<f64> = force.iter().map(|f| 2.0 * f).collect();
    let frf = welch_h1(&force, &response, DT, FRF_SEGMENT).expect("estimates");
    assert_eq!(frf.segments, 7); // (1024 − 256) / 128 + 1
    assert_eq!(frf.frequency.len(), FRF_SEGMENT / 2);
    assert!((frf.frequency[0] - 0.2).abs() < 1e-12);
    assert!(
        (frf.frequency[frf.frequency.len() - 1] - 25.6).abs() < 1e-9,
        "up to Nyquist"
    );
    for (f, db) in frf.frequency.iter().zip(&frf.magnitude_db) {
        assert!((db - 20.0 * 2f64.log10()).abs() < 1e-9, "{db} dB at {f} Hz");
    }
}

#[test]
fn h1_of_a_one_dof_oscillator_peaks_at_its_natural_frequency() {
    // ÿ = F − 2ζω ẏ − ω² y, with the force held over each sample, RK4 in 20 substeps;
    // the output is the acceleration, as from the accelerometers.
    let (natural, zeta) = (5.0, 0.02);
    let omega = 2.0 * PI * natural;
    let force = noise(5, 8192);
    let rate = |f: f64, [y, v]: [f64; 2]| [v, f - 2.0 * zeta * omega * v - omega * omega * y];
    let substeps = 20;
    let h = DT / substeps as f64;
    let mut state = [0.0, 0.0];
    let mut acceleration = Vec::with_capacity(force.len());
    for &f in &force {
        acceleration.push(rate(f, state)[1]);
        for _ in 0..substeps {
            let k1 = rate(f, state);
            let k2 = rate(f, [state[0] + 0.5 * h * k1[0], state[1] + 0.5 * h * k1[1]]);
            let k3 = rate(f, [state[0] + 0.5 * h * k2[0], state[1] + 0.5 * h * k2[1]]);
            let k4 = rate(f, [state[0] + h * k3[0], state[1] + h * k3[1]]);
            for i in 0..2 {
                state[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }
    let frf = welch_h1(&force, &acceleration, DT, FRF_SEGMENT).expect("estimates");
    let peak = (0..frf.frequency.len())
        .max_by(|&a, &b| frf.magnitude_db[a].total_cmp(&frf.magnitude_db[b]))
        .expect("bins");
    let resolution = frf.frequency[0];
    assert!(
        (frf.frequency[peak] - natural).abs() <= resolution + 1e-9,
        "peak at {} Hz, expected {natural} Hz within one bin ({resolution} Hz)",
        frf.frequency[peak]
    );
    // A resonance, not a bump: well above the mass line (|H| → 1, 0 dB) far above it.
    assert!(
        frf.magnitude_db[peak] > 20.0,
        "{} dB",
        frf.magnitude_db[peak]
    );
}

#[test]
fn renders_dataset_one_against_a_smoothed_stand_in() {
    let csv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/dataset1.csv");
    let m = crate::twin::data::Measurement::read(&csv).expect("dataset one reads");
    // Stand-in prediction, only for the picture: the measurement through a centred
    // [1/4, 1/2, 1/4] smoother, with floor 3 in anti-phase between 12 and 13 s (a residual
    // of twice the response there, ~13 band sds: severe enough for a failing window).
    let measured: Vec<Vec<f64>> = m
        .values_of(&accs())
        .expect("acc1..acc3")
        .into_iter()
        .map(<[f64]>::to_vec)
        .collect();
    let predicted: Vec<Vec<f64>> = measured
        .iter()
        .map(|acc| {
            let n = acc.len();
            (0..n)
                .map(|k| {
                    0.25 * acc[k.saturating_sub(1)] + 0.5 * acc[k] + 0.25 * acc[(k + 1).min(n - 1)]
                })
                .collect::<Vec<f64>>()
        })
        .collect();
    // The band: what the smoothing leaves, before floor 3 is pushed off.
    let noise_variance = [0, 1, 2].map(|f| {
        let residual = m
            .acc(f)
            .iter()
            .zip(&predicted[f])
            .map(|(y, p)| (y - p).powi(2));
        residual.sum::<f64>() / m.len() as f64
    });
    let mut predicted = predicted;
    for (t, p) in m.time.iter().zip(predicted[2].iter_mut()) {
        if (12.0..13.0).contains(t) {
            *p = -*p;
        }
    }
    let c = compare(
        &m.time,
        &accs(),
        &measured,
        &predicted,
        &noise_variance,
        None,
        CompareOptions::default(),
    );
    assert!(
        c.failing_windows
            .iter()
            .any(|w| w.floors.contains(&3) && w.start < 13.0 && w.end > 12.0),
        "{:?} {noise_variance:?} {:?}",
        c.failing_windows,
        c.nmse
    );

    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("dataset1.svg");
    let responses = comparison_responses(&c, &m.excitation).expect("estimates");
    plot_comparison(
        &c,
        &m.excitation.channel,
        Some(&responses),
        "dataset 1 — smoothed stand-in prediction",
        &path,
    )
    .expect("plots");
    let svg = parse_svg(&path);
    assert!(svg.texts.contains("acc2"));
    parse_svg(&dir.path().join("dataset1-frf.svg"));
}
