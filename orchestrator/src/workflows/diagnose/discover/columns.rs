//! Stage 1 of the discovery: the candidate columns of a site (the functions of the FMU's list
//! at their scales) and the site's states along the base run.

use structure::effects::{Function, Site};

use super::States;

#[derive(Clone, Copy, Debug)]
pub(super) struct Column {
    pub(super) function: Function,
    pub(super) scale: f64,
}

impl Column {
    pub(super) fn label(&self) -> String {
        if self.function.uses_scale() {
            format!("{} (s = {:.3e})", self.function.name(), self.scale)
        } else {
            self.function.name().to_string()
        }
    }
}

/// The site's `(x, v)` along the run.
pub(super) fn site_states(states: &States, site: Site) -> (Vec<f64>, Vec<f64>) {
    let n = states.drift[0].len();
    let storeys = states.drift.len();
    let mut y = vec![0.0; storeys];
    let mut v = vec![0.0; storeys];
    (0..n)
        .map(|k| {
            let mut acc = 0.0;
            for (f, yf) in y.iter_mut().enumerate() {
                acc += states.drift[f][k];
                *yf = acc;
            }
            for (f, vf) in v.iter_mut().enumerate() {
                *vf = states.velocity[f][k];
            }
            site.state(&y, &v)
        })
        .unzip()
}

pub(super) fn quantile(x: &[f64], q: f64) -> f64 {
    let mut a: Vec<f64> = x.iter().map(|v| v.abs()).collect();
    a.sort_by(f64::total_cmp);
    a[((a.len() - 1) as f64 * q) as usize]
}

/// The candidate columns of one site, from its `(x, v)` after the transient.
pub(super) fn columns(site: Site, x: &[f64], v: &[f64]) -> Vec<Column> {
    let v_rms = (v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64).sqrt();
    let mut out = Vec::new();
    for function in Function::ALL {
        // A storey's `x` and `v` are its stiffness and damping: nuisance columns already.
        if matches!(site, Site::Storey(_)) && matches!(function, Function::X | Function::V) {
            continue;
        }
        let scales: Vec<f64> = match function {
            Function::TanhV => vec![0.05 * v_rms, 0.2 * v_rms],
            Function::RampUp | Function::RampDown => {
                [0.8, 0.9, 0.95].iter().map(|&q| quantile(x, q)).collect()
            }
            _ => vec![structure::effects::discovered::DEFAULT_SCALE],
        };
        for scale in scales {
            if scale > 0.0 && scale.is_finite() {
                out.push(Column { function, scale });
            }
        }
    }
    out
}
