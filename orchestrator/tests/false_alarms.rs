//! Issue 13: on an unchanged structure, `twin diagnose` must answer `none` and `twin compare`
//! draw no failing window, whatever the excitation level and the kind of sensor noise.
//!
//! The twin is calibrated once on a 20 s record of `twin synth`'s default structure (seed 1,
//! absolute sensor noise 0.003 m/s²). Each case is a new 12 s record of the same structure
//! (seed 2) at 0.3×, 1× and 3× the calibration force, with absolute noise (`NoiseLevel::Sd`,
//! 0.003 m/s²) or response-proportional noise (`NoiseLevel::Fraction`, 3 %). The band is the twin's noise plus its parameter
//! uncertainty (`J Σ Jᵀ`), the tolerance the fallback 0.5 % (the twin has no validation records).
//! Figures per case are printed (`--nocapture`) and quoted in the README.
//!
//! Needs the FMUs: `scripts/build-fmus.sh` (found through `TWIN_FMU_DIR`).

use std::sync::OnceLock;

use orchestrator::data::Measurement;
use orchestrator::diagnose::{diagnose, Action, DiagnoseOptions, Diagnosis};
use orchestrator::run::{run_and_compare, FALLBACK_TOLERANCE};
use orchestrator::synth::{synth_record, BetweenSamples, NoiseLevel, Scenario, DEFAULT_FORCE_RMS};
use orchestrator::twin::Twin;

mod common;
use common::{twin_calibrated_on_default_structure, worst};

const NOISE_SD: f64 = 0.003;
const NOISE_FRACTION: f64 = 0.03;

fn twin() -> &'static Twin {
    static TWIN: OnceLock<Twin> = OnceLock::new();
    TWIN.get_or_init(|| twin_calibrated_on_default_structure(NOISE_SD))
}

fn record(gain: f64, noise: NoiseLevel, between: BetweenSamples) -> Measurement {
    let mut s = Scenario {
        seed: 2,
        duration: 12.0,
        ..Scenario::default()
    };
    s.force.rms = gain * DEFAULT_FORCE_RMS;
    s.force.between_samples = between;
    s.noise.level = noise;
    synth_record(&s).expect("synth").0.measurement
}

/// Diagnose and compare; `none`, no failing window; the figures printed.
fn unchanged(label: &str, data: &Measurement) -> Diagnosis {
    let t = std::time::Instant::now();
    let d = diagnose(twin(), data, &DiagnoseOptions::default()).expect("diagnosis");
    let c = run_and_compare(twin(), data, 2.0, |_, _| {}).expect("compare");
    eprintln!(
        "{label}: NMSE {:.4} / {:.4} / {:.4} %, explained {:.4} / {:.4} / {:.4} % (parameter \
         share {:.2e} %), tolerance {} % ({}), statistically {}, action {}, failing windows {} \
         ({} below the tolerance), {:.2} s",
        d.nmse_before[0],
        d.nmse_before[1],
        d.nmse_before[2],
        d.explained_nmse[0],
        d.explained_nmse[1],
        d.explained_nmse[2],
        worst(&d.band_nmse),
        d.tolerance,
        d.tolerance_source,
        d.statistically_significant,
        d.action.name(),
        c.comparison.failing_windows.len(),
        c.comparison.windows_below_tolerance,
        t.elapsed().as_secs_f64()
    );
    assert_eq!(d.action, Action::None, "{label}: {}", d.reason);
    assert!(d.effect.is_none());
    assert!(
        c.comparison.failing_windows.is_empty(),
        "{label}: {:?}",
        c.comparison.failing_windows
    );
    assert!(d.failing_windows.is_empty(), "{label}");
    // The band includes the parameter uncertainty: positive, and in the report.
    assert!(
        d.band_nmse.iter().all(|b| *b > 0.0),
        "{label}: {:?}",
        d.band_nmse
    );
    assert_eq!(d.tolerance, FALLBACK_TOLERANCE);
    d
}

#[test]
fn absolute_sensor_noise_at_three_excitation_levels() {
    for gain in [0.3, 1.0, 3.0] {
        let data = record(
            gain,
            NoiseLevel::Sd(vec![NOISE_SD; 3]),
            BetweenSamples::Linear,
        );
        unchanged(&format!("sd {gain}×"), &data);
    }
}

#[test]
fn response_proportional_noise_at_three_excitation_levels() {
    for gain in [0.3, 1.0, 3.0] {
        let data = record(
            gain,
            NoiseLevel::Fraction(vec![NOISE_FRACTION; 3]),
            BetweenSamples::Linear,
        );
        let d = unchanged(&format!("fraction {gain}×"), &data);
        if gain == 3.0 {
            // The twin's noise variance is absolute and this noise grew with the response: the
            // statistics flag it, and only practical significance keeps it `none` (measured: NMSE
            // ~0.09 % against an explained level of ~0.02 %).
            assert!(d.statistically_significant, "{}", d.reason);
            assert!(!d.practically_significant);
        }
    }
}

#[test]
fn the_band_is_j_sigma_j_and_grows_with_the_covariance() {
    // J Σ Jᵀ is linear in Σ: the twin with its covariance ×10⁴ has a parameter band 10⁴ × as
    // large (to 1 %), and that band, once it explains the error, makes the statistics quiet.
    let data = record(
        3.0,
        NoiseLevel::Fraction(vec![NOISE_FRACTION; 3]),
        BetweenSamples::Linear,
    );
    let base = run_and_compare(twin(), &data, 2.0, |_, _| {}).expect("compare");
    let mut wide = twin().duplicate();
    let cov = wide.parameter_covariance.as_mut().expect("a covariance");
    assert_eq!(cov.names.len(), 9);
    for row in cov.matrix.iter_mut() {
        for x in row.iter_mut() {
            *x *= 1e4;
        }
    }
    let widened = run_and_compare(&wide, &data, 2.0, |_, _| {}).expect("compare");
    for f in 0..3 {
        let ratio = widened.band_nmse[f] / base.band_nmse[f];
        assert!((ratio / 1e4 - 1.0).abs() < 0.01, "floor {}: {ratio}", f + 1);
    }
    let strict = DiagnoseOptions {
        tolerance: Some(0.0),
        ..DiagnoseOptions::default()
    };
    let d = diagnose(&wide, &data, &strict).expect("diagnosis");
    eprintln!(
        "covariance ×1e4: explained {:?}, NMSE {:?}: {}",
        d.explained_nmse, d.nmse_before, d.reason
    );
    assert!(!d.statistically_significant, "{}", d.reason);
    assert_eq!(d.action, Action::None);
}

#[test]
fn the_covariance_and_validation_level_survive_the_archive() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("t.ssp");
    let mut t = twin().duplicate();
    t.validation_nmse = Some(0.123);
    t.write(&path).expect("write");
    let back = Twin::read(&path).expect("read");
    let (a, b) = (
        t.parameter_covariance.as_ref().expect("covariance"),
        back.parameter_covariance.as_ref().expect("read back"),
    );
    for (i, name) in a.names.iter().enumerate() {
        let j = b.names.iter().position(|n| n == name).expect(name);
        for (k, other) in a.names.iter().enumerate() {
            let l = b.names.iter().position(|n| n == other).expect(other);
            assert_eq!(a.matrix[i][k], b.matrix[j][l], "{name}, {other}");
        }
    }
    assert_eq!(back.validation_nmse, Some(0.123));
    // The default tolerance follows the validation level.
    let data = record(
        1.0,
        NoiseLevel::Sd(vec![NOISE_SD; 3]),
        BetweenSamples::Linear,
    );
    let d = diagnose(&back, &data, &DiagnoseOptions::default()).expect("diagnosis");
    assert!((d.tolerance - 0.246).abs() < 1e-12, "{}", d.tolerance);
    assert!(d.tolerance_source.contains("validation"));
}
