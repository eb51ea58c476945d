use fmi2::{CoSimModel, InstantiateContext};

use super::*;
use crate::lags::lagged_inputs;
use crate::layout::select;

/// A layout of four channels under ground motion, trained on a small record with given
/// hyperparameters, instantiated from its bundled training file: its table is the layout's,
/// each channel's outputs are its GP's on the columns the layout chooses, learning through
/// `do_step` adds the sample to every channel, and the training file written back holds the
/// whole lag vectors the corrector saw.
#[test]
fn a_corrector_of_another_layout_predicts_each_channel_from_its_own_inputs() {
    let layout =
        Layout::from_names(&["acc1", "acc3", "acc5", "vel2"], "ground_acc").expect("test value");
    let (m, lags) = (layout.channels.len(), 1);
    let samples: Vec<Vec<f64>> = (0..30)
        .map(|k| {
            (0..=m)
                .map(|c| (0.3 * k as f64 + c as f64).sin() * (1.0 + c as f64 * 0.1))
                .collect()
        })
        .collect();
    let inputs = lagged_inputs(&samples, lags);
    let targets: Vec<Vec<f64>> = samples
        .iter()
        .map(|s| (0..m).map(|j| 0.1 * s[j] * s[m]).collect())
        .collect();
    let hyperparameters: Vec<FloorHyperparameters> = (0..m)
        .map(|j| FloorHyperparameters {
            length_scales: vec![0.8 + 0.1 * j as f64; layout.input_dimension_of(j, lags)],
            signal_variance: 0.01,
            noise_variance: 1e-4,
        })
        .collect();
    let file = LayoutTraining {
        channels: layout.names(),
        excitation: layout.excitation_name(),
        lags,
        target: TargetForm::Discrepancy,
        inputs: inputs[..20].to_vec(),
        targets: targets[..20].to_vec(),
        hyperparameters: Some(hyperparameters.clone()),
    };
    let dir = tempfile::tempdir().expect("temp dir");
    file.write(&dir.path().join(BUNDLED_TRAINING_FILE))
        .expect("written");
    let context = InstantiateContext {
        instance_name: "layout".into(),
        resource_dir: Some(dir.path().to_path_buf()),
    };
    let mut model = GpCorrector::instantiate(&context).expect("instantiate");
    assert_eq!(model.layout, layout);
    let table = model.table();
    assert_eq!(table.guid, crate::variables::table(&layout).guid);
    assert!(table.by_name("sd_vel2").is_some() && table.by_name("force").is_none());
    model.set_integer(LAGS, lags as i32).expect("lags");
    model.set_integer(REFIT_EVERY, 0).expect("refit_every");
    model.exit_initialization().expect("initialize");
    let gp = |j: usize, points: usize| {
        let rows: Vec<Vec<f64>> = inputs[..points]
            .iter()
            .map(|x| select(x, &layout.columns_of(j), lags))
            .collect();
        let h = &hyperparameters[j];
        GaussianProcess::new(
            Inputs::from_rows(&rows).expect("test value"),
            targets[..points].iter().map(|y| y[j]).collect(),
            Hyperparameters::new(&h.length_scales, h.signal_variance, h.noise_variance)
                .expect("test value"),
        )
        .expect("test value")
    };
    for (k, sample) in samples.iter().enumerate().take(25) {
        for (j, &value) in sample.iter().enumerate().take(m) {
            model
                .set_real(vr_of(&layout, Role::Physics, j), value)
                .expect("test value");
            model
                .set_real(vr_of(&layout, Role::Measured, j), sample[j] + targets[k][j])
                .expect("test value");
        }
        model.set_real(GROUND_ACC, sample[m]).expect("test value");
        // From sample 20 on the corrector learns each sample after reading it.
        model.set_boolean(LEARN, k >= 20).expect("test value");
        let known = if k <= 20 { 20 } else { k };
        for (j, &physics) in sample.iter().enumerate().take(m) {
            let x = select(&inputs[k], &layout.columns_of(j), lags);
            let p = gp(j, known).predict_point(&x).expect("test value");
            let corrected = model
                .get_real(vr_of(&layout, Role::Corrected, j))
                .expect("test value");
            let latent = model
                .get_real(vr_of(&layout, Role::LatentVar, j))
                .expect("test value");
            let expected = physics + p.mean;
            assert!(
                (corrected - expected).abs() <= 1e-9 * expected.abs().max(1e-6),
                "sample {k}, {}: {corrected} vs {expected}",
                layout.channels[j].name()
            );
            assert!(
                (latent - p.latent_variance).abs() <= 1e-9 * p.latent_variance.max(1e-9),
                "sample {k}, {}: {latent} vs {}",
                layout.channels[j].name(),
                p.latent_variance
            );
        }
        model.do_step(k as f64, 1.0).expect("test value");
    }
    let learned = model.training().expect("built");
    assert_eq!(learned.inputs, inputs[..25].to_vec());
    assert_eq!(learned.channels, layout.names());
    for (a, b) in learned.targets.iter().zip(&targets[..25]) {
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= 1e-12, "{x} vs {y}");
        }
    }
    assert!(model.training_file().is_none(), "not the rig's format");
}
