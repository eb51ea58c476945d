//! The stabilisation diagram and the automatic choice of the physical modes in it.
//!
//! An identification method returns poles per model order ([`ModelOrder`]). The diagram flags
//! each pole stable in frequency, damping and shape against the nearest pole of the previous
//! order. The selection keeps the stable, physical poles (positive, bounded damping; shape
//! nearly real by MPC / MPD), clusters them by frequency distance and shape (1 − MAC), keeps
//! the clusters populated over enough orders, and reports per mode the median frequency and
//! damping, a representative shape, their scatter over the cluster, MPC and MPD.

use std::f64::consts::PI;

use super::Complex;
use serde::{Deserialize, Serialize};

use super::error::IdentificationError;
use super::indicators::{mac, mpc, mpd};

/// A pole of an identified model: its eigenvalue λ (rad/s, continuous time), frequency
/// `|λ| / 2π` (Hz), damping ratio `−Re λ / |λ|`, mode shape (over the measured channels,
/// scaled so its largest component is 1) and the shape's MPC and MPD (degrees).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pole {
    pub eigenvalue: Complex,
    pub frequency: f64,
    pub damping: f64,
    pub shape: Vec<Complex>,
    pub mpc: f64,
    pub mpd: f64,
    #[serde(default)]
    pub stable: Stability,
}

/// Whether a pole agrees with the nearest pole of the previous order.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stability {
    pub frequency: bool,
    pub damping: bool,
    pub shape: bool,
}

impl Stability {
    pub fn all(&self) -> bool {
        self.frequency && self.damping && self.shape
    }
}

impl Pole {
    /// The pole of eigenvalue `eigenvalue` (rad/s) with mode shape `shape`.
    pub fn new(eigenvalue: Complex, shape: Vec<Complex>) -> Pole {
        let modulus = eigenvalue.norm();
        let shape = normalised(shape);
        Pole {
            eigenvalue,
            frequency: modulus / (2.0 * PI),
            damping: if modulus > 0.0 {
                -eigenvalue.re / modulus
            } else {
                0.0
            },
            mpc: mpc(&shape),
            mpd: mpd(&shape),
            shape,
            stable: Stability::default(),
        }
    }
}

/// `shape` scaled so its largest component is 1 (real); unchanged if it is zero.
pub fn normalised(shape: Vec<Complex>) -> Vec<Complex> {
    let largest = shape
        .iter()
        .copied()
        .max_by(|a, b| a.norm().total_cmp(&b.norm()));
    match largest {
        Some(l) if l.norm() > 0.0 => shape.into_iter().map(|v| v / l).collect(),
        _ => shape,
    }
}

/// The poles (one of each complex-conjugate pair, positive imaginary part) of one model order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelOrder {
    pub order: usize,
    pub poles: Vec<Pole>,
}

/// When a pole counts as stable against the previous order.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StabilityTolerances {
    /// Relative frequency change.
    pub frequency: f64,
    /// Relative damping change.
    pub damping: f64,
    /// Least MAC with the previous order's pole.
    pub mac: f64,
}

impl Default for StabilityTolerances {
    /// 1 % in frequency, 5 % in damping, MAC 0.98: the usual defaults of OMA tools.
    fn default() -> Self {
        StabilityTolerances {
            frequency: 0.01,
            damping: 0.05,
            mac: 0.98,
        }
    }
}

impl StabilityTolerances {
    pub fn validate(&self) -> Result<(), IdentificationError> {
        fraction("frequency tolerance", self.frequency)?;
        fraction("damping tolerance", self.damping)?;
        fraction("stability MAC", self.mac)
    }
}

fn fraction(what: &'static str, value: f64) -> Result<(), IdentificationError> {
    if value.is_finite() && value > 0.0 && value <= 1.0 {
        Ok(())
    } else {
        Err(IdentificationError::Option {
            what,
            value,
            rule: "a fraction in (0, 1]".into(),
        })
    }
}

/// Poles per model order, each flagged against the previous order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StabilisationDiagram {
    pub orders: Vec<ModelOrder>,
    pub tolerances: StabilityTolerances,
}

impl StabilisationDiagram {
    /// Flags every pole of `orders` (ascending order) against the nearest pole in frequency of
    /// the order before it; the first order's poles are not stable.
    pub fn new(
        mut orders: Vec<ModelOrder>,
        tolerances: StabilityTolerances,
    ) -> Result<StabilisationDiagram, IdentificationError> {
        tolerances.validate()?;
        orders.sort_by_key(|o| o.order);
        for k in 1..orders.len() {
            let (before, after) = orders.split_at_mut(k);
            let previous = &before[k - 1].poles;
            for pole in &mut after[0].poles {
                let nearest = previous.iter().min_by(|a, b| {
                    (a.frequency - pole.frequency)
                        .abs()
                        .total_cmp(&(b.frequency - pole.frequency).abs())
                });
                if let Some(p) = nearest {
                    pole.stable = Stability {
                        frequency: relative(pole.frequency, p.frequency) <= tolerances.frequency,
                        damping: relative(pole.damping, p.damping) <= tolerances.damping,
                        shape: mac(&pole.shape, &p.shape) >= tolerances.mac,
                    };
                }
            }
        }
        Ok(StabilisationDiagram { orders, tolerances })
    }
}

fn relative(a: f64, reference: f64) -> f64 {
    if reference != 0.0 {
        ((a - reference) / reference).abs()
    } else {
        f64::INFINITY
    }
}

/// How the physical modes are chosen from a diagram.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SelectionOptions {
    /// A damping ratio above this is not a structural mode.
    pub max_damping: f64,
    /// Least MPC of a physical mode's shape.
    pub min_mpc: f64,
    /// Largest MPD (degrees) of a physical mode's shape.
    pub max_mpd: f64,
    /// Poles of one cluster lie within this relative frequency distance of its last pole.
    pub cluster_frequency: f64,
    /// ... and have at least this MAC with its last pole's shape.
    pub cluster_mac: f64,
    /// A cluster is a mode when it holds poles from at least this fraction of the diagram's
    /// orders (and from at least [`MIN_CLUSTER_POLES`]).
    pub min_fraction: f64,
    /// Whether a pole must also be stable in damping to join a cluster. A fit of an FRF
    /// (LSCF) does without: a lightly damped mode narrower than the FRF's bins has a damping
    /// each order reads from the window's leakage, jumping by more than any tolerance while its
    /// frequency holds (a lab frame's first mode, 0.4 % at 3.17 Hz in 0.12 Hz bins, was lost
    /// that way); its damping is judged over the cluster (the mode's damping sd).
    #[serde(default = "stable_damping")]
    pub damping_stability: bool,
}

fn stable_damping() -> bool {
    true
}

/// The fewest poles a mode is made of, whatever the fraction.
pub const MIN_CLUSTER_POLES: usize = 3;

impl Default for SelectionOptions {
    fn default() -> Self {
        SelectionOptions {
            max_damping: 0.2,
            min_mpc: 0.7,
            max_mpd: 30.0,
            cluster_frequency: 0.01,
            cluster_mac: 0.95,
            min_fraction: 0.3,
            damping_stability: true,
        }
    }
}

impl SelectionOptions {
    /// Whether `pole` may join a cluster: stable against the previous order (in damping too
    /// when [`SelectionOptions::damping_stability`]), positively and not overly damped, its
    /// shape nearly real.
    pub fn physical(&self, p: &Pole) -> bool {
        p.stable.frequency
            && p.stable.shape
            && (p.stable.damping || !self.damping_stability)
            && p.damping > 0.0
            && p.damping <= self.max_damping
            && p.mpc >= self.min_mpc
            && p.mpd <= self.max_mpd
    }

    pub fn validate(&self) -> Result<(), IdentificationError> {
        fraction("largest damping", self.max_damping)?;
        if !(self.min_mpc.is_finite() && (0.0..=1.0).contains(&self.min_mpc)) {
            return Err(IdentificationError::Option {
                what: "least MPC",
                value: self.min_mpc,
                rule: "within [0, 1]".into(),
            });
        }
        if !(self.max_mpd.is_finite() && (0.0..=90.0).contains(&self.max_mpd)) {
            return Err(IdentificationError::Option {
                what: "largest MPD",
                value: self.max_mpd,
                rule: "degrees within [0, 90]".into(),
            });
        }
        fraction("cluster frequency distance", self.cluster_frequency)?;
        fraction("cluster MAC", self.cluster_mac)?;
        fraction("least fraction of orders", self.min_fraction)
    }
}

/// A mode chosen from the diagram: medians over its cluster and their scatter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IdentifiedMode {
    /// Hz: the median over the cluster, and the standard deviation over it.
    pub frequency: f64,
    pub frequency_sd: f64,
    pub damping: f64,
    pub damping_sd: f64,
    /// The shape of the cluster's pole nearest the median frequency, largest component 1.
    pub shape: Vec<Complex>,
    /// Per component: the rms distance of the cluster's shapes (each scaled onto `shape`) from
    /// it.
    pub shape_sd: Vec<f64>,
    pub mpc: f64,
    pub mpd: f64,
    /// The model orders whose poles make the cluster.
    pub orders: Vec<usize>,
}

struct Cluster<'a> {
    poles: Vec<(usize, &'a Pole)>,
}

impl Cluster<'_> {
    fn last(&self) -> &Pole {
        self.poles[self.poles.len() - 1].1
    }
}

/// The physical modes of `diagram`, by ascending frequency.
pub fn select_modes(
    diagram: &StabilisationDiagram,
    options: &SelectionOptions,
) -> Result<Vec<IdentifiedMode>, IdentificationError> {
    options.validate()?;
    let physical = |p: &Pole| options.physical(p);
    let mut clusters: Vec<Cluster<'_>> = Vec::new();
    for order in &diagram.orders {
        for pole in order.poles.iter().filter(|p| physical(p)) {
            let home = clusters
                .iter()
                .enumerate()
                .filter(|(_, c)| {
                    c.poles.iter().all(|(o, _)| *o != order.order)
                        && relative(pole.frequency, c.last().frequency) <= options.cluster_frequency
                        && mac(&pole.shape, &c.last().shape) >= options.cluster_mac
                })
                .min_by(|(_, a), (_, b)| {
                    relative(pole.frequency, a.last().frequency)
                        .total_cmp(&relative(pole.frequency, b.last().frequency))
                })
                .map(|(i, _)| i);
            match home {
                Some(i) => clusters[i].poles.push((order.order, pole)),
                None => clusters.push(Cluster {
                    poles: vec![(order.order, pole)],
                }),
            }
        }
    }
    let needed = ((options.min_fraction * diagram.orders.len() as f64).ceil() as usize)
        .max(MIN_CLUSTER_POLES);
    let mut modes: Vec<IdentifiedMode> = clusters
        .iter()
        .filter(|c| c.poles.len() >= needed)
        .map(summarise)
        .collect();
    modes.sort_by(|a, b| a.frequency.total_cmp(&b.frequency));
    Ok(modes)
}

/// The stable, physical poles ([`SelectionOptions::physical`]: stable against the order
/// below) of the diagram's highest order that no mode of `modes` is made of (none within the
/// cluster distance of its frequency): modes still forming when the sweep ended. A broad band
/// needs more orders than a narrow one before its modes stand (a five-storey tower's fourth
/// and fifth modes, fitted over 0–40 Hz, stood from order 32 of 40, too few orders to make a
/// cluster); a method sweeps on while this is not empty.
pub fn forming_poles<'a>(
    diagram: &'a StabilisationDiagram,
    options: &SelectionOptions,
    modes: &[IdentifiedMode],
) -> Vec<&'a Pole> {
    let Some(top) = diagram.orders.last() else {
        return Vec::new();
    };
    top.poles
        .iter()
        .filter(|p| {
            options.physical(p)
                && modes
                    .iter()
                    .all(|m| relative(p.frequency, m.frequency) > options.cluster_frequency)
        })
        .collect()
}

/// Why a stable, physical-looking mode is not reported as a mode of the structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rejection {
    /// Within [`ScreenOptions::edge`] of an edge of the band the measured force excites: the
    /// force's spectrum falling off, which an output-only method (and a fit of the FRF near
    /// where it ends) reads as a pole.
    ExcitationEdge,
    /// Outside the band the measured force excites: nothing there was driven to respond.
    OutsideExcitation,
    /// At the measured force's own spectral peak (a mass damper's or a shaker's narrow band
    /// over a broad floor), where no FRF peaks: the responses peak there because the force
    /// does, and an output-only method reads that peak as a lightly damped pole.
    Excitation,
    /// Its shape is one channel (of at least [`ONE_CHANNEL_AMONG`]): the largest component
    /// holds [`ScreenOptions::one_channel`] of the shape's power or more — noise, or a
    /// sensor's own resonance, not a mode of a frame whose floors move together.
    OneChannel,
    /// Closer to a mode made of more poles than the record can resolve
    /// ([`ScreenOptions::resolution`]), or within [`ScreenOptions::split_frequency`] of it
    /// with the same shape (MAC at least [`ScreenOptions::split_mac`]): one resonance the fit
    /// split in two.
    Unresolved,
    /// No measured curve (an FRF's magnitude, or the responses' spectrum) peaks at its
    /// frequency ([`peak_supported`]): a pole the fit made of noise.
    NoPeak,
    /// Found in fewer than half of a roving test's runs (each run fitted alone).
    FewRuns,
    /// Its cluster holds poles from too few model orders beside the best-supported mode's: a
    /// pole the fit makes of noise at some orders and not at others.
    FewOrders,
    /// An FRF fit's mode whose own fitted term stands no higher than the fit's misfit around
    /// it: a pole made of the FRF's noise, which it explains no better than the noise does.
    BelowMisfit,
    /// A lightly damped mode the record taken whole in the time domain (through its measured
    /// force) does not need: left out of the fit, the residual rises by less than a small
    /// share of itself — a pole the FRF fit made of noise, or of a nonlinearity's trace (a
    /// contact's harmonics), not a resonance the force drove.
    NotInRecord,
    /// An FRF fit of too few channels for a shape to tell noise from a mode: formed only past
    /// the model orders asked for, where no FRF peak took the sweep on: a pole of the
    /// higher orders' noise.
    Unsought,
    /// An FDD peak where the spectral matrix's first singular value is less than
    /// [`crate::modal::fdd::SEPARATION`] times its second: no one shape holds the peak, a
    /// chance maximum of the noise between modes.
    Unseparated,
}

impl Rejection {
    pub fn reason(self) -> &'static str {
        match self {
            Rejection::ExcitationEdge => "at the edge of the force's band (excitation)",
            Rejection::OutsideExcitation => "outside the force's band (excitation)",
            Rejection::Excitation => {
                "at the force's own spectral peak, where the FRF does not peak (excitation)"
            }
            Rejection::OneChannel => "its shape is one channel",
            Rejection::Unresolved => {
                "one resonance with a stronger mode (within the record's resolution, or as close \
                 with its shape)"
            }
            Rejection::NoPeak => "no peak of the measured FRF or spectrum there",
            Rejection::FewRuns => "found in fewer than half of the roving runs",
            Rejection::BelowMisfit => "its fitted term no larger than the fit's misfit (noise)",
            Rejection::NotInRecord => {
                "the record taken whole explains next to nothing more with it (noise, or a \
                 nonlinearity's trace)"
            }
            Rejection::Unsought => {
                "formed only past the orders asked for, at no peak the sweep went on for (a \
                 pole of noise on too few channels for a shape)"
            }
            Rejection::FewOrders => {
                "found at too few model orders beside the best-supported mode (a pole of noise)"
            }
            Rejection::Unseparated => {
                "no one shape holds the spectral matrix at the peak (its first singular value \
                 under 50 times the second: noise)"
            }
        }
    }
}

/// The fewest channels at which a one-channel shape is rejected.
pub const ONE_CHANNEL_AMONG: usize = 3;

/// What [`screen_modes`] knows of the excitation, and its thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScreenOptions {
    /// Hz: the band the measured force excites (None: not measured, an ambient record).
    pub excited: Option<(f64, f64)>,
    /// Whether each end of `excited` is an edge (the force's power falls off there), rather
    /// than the end of the record's band.
    pub edges: (bool, bool),
    /// Relative distance from an edge within which a mode is the excitation's.
    pub edge: f64,
    /// The share of a shape's power in its largest component that makes it one channel.
    pub one_channel: f64,
    /// Hz: two modes closer than this are one (the record's frequency resolution: a Welch
    /// bin); None: every mode stands.
    pub resolution: Option<f64>,
    /// Two modes within this relative frequency distance whose shapes have a MAC of at least
    /// [`ScreenOptions::split_mac`] are one resonance the fit split: a 0.3 %-damped tower
    /// mode's leaky FRF peak, 1.2 bins wide, came out of LSCF as two modes 0.58 % apart
    /// with the same shape (MAC 1.0000 both with the exact one). Modes of a frame differ in
    /// shape; on one channel every shape is alike, and modes this close are one peak.
    #[serde(default = "split_frequency")]
    pub split_frequency: f64,
    #[serde(default = "split_mac")]
    pub split_mac: f64,
}

fn split_frequency() -> f64 {
    0.01
}

fn split_mac() -> f64 {
    0.95
}

impl Default for ScreenOptions {
    /// No measured force; 5 % from an edge; 90 % of the power in one channel.
    fn default() -> Self {
        ScreenOptions {
            excited: None,
            edges: (false, false),
            edge: 0.05,
            one_channel: 0.9,
            resolution: None,
            split_frequency: split_frequency(),
            split_mac: split_mac(),
        }
    }
}

impl ScreenOptions {
    pub fn validate(&self) -> Result<(), IdentificationError> {
        fraction("distance from the force's band edge", self.edge)?;
        fraction("one channel's share of a shape", self.one_channel)?;
        fraction("split modes' frequency distance", self.split_frequency)?;
        fraction("split modes' MAC", self.split_mac)?;
        match self.resolution {
            Some(r) if !(r.is_finite() && r > 0.0) => Err(IdentificationError::Option {
                what: "frequency resolution",
                value: r,
                rule: "positive Hz".into(),
            }),
            _ => Ok(()),
        }
    }
}

/// A mode set aside by [`screen_modes`], with the reason.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RejectedMode {
    #[serde(flatten)]
    pub mode: IdentifiedMode,
    pub rejection: Rejection,
    pub reason: String,
}

impl RejectedMode {
    /// `mode` set aside for `rejection`, with its reason in words.
    pub fn new(mode: IdentifiedMode, rejection: Rejection) -> Self {
        RejectedMode {
            reason: rejection.reason().to_owned(),
            mode,
            rejection,
        }
    }
}

/// Splits `modes` into those of the structure and those set aside as the excitation's or a
/// single channel's ([`Rejection`]), each list by ascending frequency.
pub fn screen_modes(
    modes: Vec<IdentifiedMode>,
    options: &ScreenOptions,
) -> (Vec<IdentifiedMode>, Vec<RejectedMode>) {
    let mut kept = Vec::new();
    let mut rejected = Vec::new();
    let unresolved = unresolved_modes(&modes, options);
    for (index, mode) in modes.into_iter().enumerate() {
        let f = mode.frequency;
        let near = |edge: f64| relative(f, edge) <= options.edge;
        let rejection = match options.excited {
            Some((low, high))
                if (options.edges.0 && near(low)) || (options.edges.1 && near(high)) =>
            {
                Some(Rejection::ExcitationEdge)
            }
            Some((low, high)) if (options.edges.0 && f < low) || (options.edges.1 && f > high) => {
                Some(Rejection::OutsideExcitation)
            }
            _ => None,
        }
        .or_else(|| {
            let power: f64 = mode.shape.iter().map(|v| v.norm_sqr()).sum();
            let largest = mode.shape.iter().map(|v| v.norm_sqr()).fold(0.0, f64::max);
            (mode.shape.len() >= ONE_CHANNEL_AMONG
                && power > 0.0
                && largest >= options.one_channel * power)
                .then_some(Rejection::OneChannel)
        })
        .or_else(|| unresolved[index].then_some(Rejection::Unresolved));
        match rejection {
            None => kept.push(mode),
            Some(rejection) => rejected.push(RejectedMode::new(mode, rejection)),
        }
    }
    (kept, rejected)
}

/// How far (relative) either side of a mode a measured curve is searched for its fall.
pub const PEAK_SPAN: f64 = 0.1;
/// How many times a mode's peak stands above the lower of the curve on each side of it.
pub const PEAK_PROMINENCE: f64 = 2.0;

/// Magnitudes measured over frequency (an FRF's per channel, or the square root of a
/// spectrum) that a mode must show as a peak.
#[derive(Debug, Clone, Copy)]
pub struct PeakEvidence<'a> {
    /// Hz, ascending, evenly spaced.
    pub frequencies: &'a [f64],
    /// Per curve, per frequency.
    pub curves: &'a [Vec<f64>],
    /// Per curve, per frequency, the coherence of an FRF's curve with the force: a curve
    /// supports a mode only where it reaches [`PEAK_COHERENCE`] (None: a spectrum).
    pub coherence: Option<&'a [Vec<f64>]>,
}

/// The least coherence at a mode's peak for an FRF to support it: below it the FRF there is
/// the sensors' noise over the force.
pub const PEAK_COHERENCE: f64 = 0.5;

impl PeakEvidence<'_> {
    /// Whether some curve peaks at `frequency`: its largest value within two bins of it is at
    /// least [`PEAK_PROMINENCE`] times its least value on each side within [`PEAK_SPAN`]
    /// (beyond the two bins); a side the curve does not reach is not asked. True when no
    /// curve reaches the frequency (nothing to judge by).
    pub fn supports(&self, frequency: f64) -> bool {
        let bin = match self.frequencies {
            [a, b, ..] if b > a => b - a,
            _ => return true,
        };
        let near = 2.0 * bin;
        let span = (PEAK_SPAN * frequency).max(2.0 * near);
        let within = |from: f64, to: f64| {
            self.frequencies
                .iter()
                .enumerate()
                .filter(move |(_, f)| **f >= from && **f <= to)
                .map(|(k, _)| k)
        };
        let peak_bins: Vec<usize> = within(frequency - near, frequency + near).collect();
        if peak_bins.is_empty() {
            return true;
        }
        let left: Vec<usize> = within(frequency - span, frequency - near - 0.5 * bin).collect();
        let right: Vec<usize> = within(frequency + near + 0.5 * bin, frequency + span).collect();
        self.curves.iter().enumerate().any(|(i, curve)| {
            let coherent = match self.coherence {
                None => true,
                Some(c) => peak_bins.iter().map(|k| c[i][*k]).fold(0.0, f64::max) >= PEAK_COHERENCE,
            };
            if !coherent {
                return false;
            }
            let peak = peak_bins.iter().map(|k| curve[*k]).fold(0.0, f64::max);
            let floor =
                |side: &[usize]| side.iter().map(|k| curve[*k]).fold(f64::INFINITY, f64::min);
            let valley = match (left.is_empty(), right.is_empty()) {
                (true, true) => return true,
                (true, false) => floor(&right),
                (false, true) => floor(&left),
                (false, false) => floor(&left).max(floor(&right)),
            };
            peak > 0.0 && peak >= PEAK_PROMINENCE * valley
        })
    }
}

/// Moves the modes of `kept` that `evidence` does not show as a peak to `rejected`
/// ([`Rejection::NoPeak`]).
pub fn screen_by_peaks(
    kept: Vec<IdentifiedMode>,
    rejected: &mut Vec<RejectedMode>,
    evidence: &PeakEvidence<'_>,
) -> Vec<IdentifiedMode> {
    let (supported, unsupported): (Vec<_>, Vec<_>) = kept
        .into_iter()
        .partition(|m| evidence.supports(m.frequency));
    rejected.extend(
        unsupported
            .into_iter()
            .map(|mode| RejectedMode::new(mode, Rejection::NoPeak)),
    );
    rejected.sort_by(|a, b| a.mode.frequency.total_cmp(&b.mode.frequency));
    supported
}

/// Per mode (ascending frequency), whether a mode that is the same resonance — within the
/// options' resolution (Hz), or with the same shape within their split distance or within
/// [`half_power_overlap`] — is made of more poles (ties: the earlier one stands).
fn unresolved_modes(modes: &[IdentifiedMode], options: &ScreenOptions) -> Vec<bool> {
    let same = |a: &IdentifiedMode, b: &IdentifiedMode| {
        let apart = (a.frequency - b.frequency).abs();
        options.resolution.is_some_and(|r| apart < r)
            || ((relative(a.frequency, b.frequency) <= options.split_frequency
                || apart < half_power_overlap(a, b))
                && mac(&a.shape, &b.shape) >= options.split_mac)
    };
    modes
        .iter()
        .enumerate()
        .map(|(i, mode)| {
            modes.iter().enumerate().any(|(j, other)| {
                j != i
                    && same(mode, other)
                    && (other.orders.len() > mode.orders.len()
                        || (other.orders.len() == mode.orders.len() && j < i))
            })
        })
        .collect()
}

/// Hz: the sum of two modes' half-power half-widths (`ζ f` each). Two modes of the same
/// shape closer than this make one hump in every channel: nothing measured tells them apart,
/// and the fit split one resonance in two. The paper rig's 20 s dataset1 had LSCF's
/// 1.9484 Hz (ζ 1.47 %) and 2.0187 Hz (ζ 2.97 %), 0.070 Hz apart (1.4 of its bins) within
/// 0.089 Hz, MAC 0.999; dataset2 5.7533 Hz (1.71 %) and 5.9635 Hz (2.07 %), 0.210 within
/// 0.222 Hz. A frame's close modes differ in shape (a tall tower's 8.458 and 8.753 Hz, 0.295
/// apart within 0.344 Hz at 2 %, stand by their MAC).
pub fn half_power_overlap(a: &IdentifiedMode, b: &IdentifiedMode) -> f64 {
    a.damping.max(0.0) * a.frequency + b.damping.max(0.0) * b.frequency
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

fn sd(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    if values.len() < 2 {
        return 0.0;
    }
    let mean = values.iter().sum::<f64>() / n;
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}

fn summarise(cluster: &Cluster<'_>) -> IdentifiedMode {
    let frequencies: Vec<f64> = cluster.poles.iter().map(|(_, p)| p.frequency).collect();
    let dampings: Vec<f64> = cluster.poles.iter().map(|(_, p)| p.damping).collect();
    let frequency = median(&mut frequencies.clone());
    let damping = median(&mut dampings.clone());
    let representative = cluster
        .poles
        .iter()
        .map(|(_, p)| *p)
        .min_by(|a, b| {
            (a.frequency - frequency)
                .abs()
                .total_cmp(&(b.frequency - frequency).abs())
        })
        .unwrap_or(cluster.last());
    let shape = representative.shape.clone();
    let mut squared = vec![0.0; shape.len()];
    for (_, pole) in &cluster.poles {
        // The complex scale that best maps the pole's shape onto the representative one.
        let along: Complex = pole
            .shape
            .iter()
            .zip(&shape)
            .map(|(v, r)| v.conj() * r)
            .sum();
        let power: f64 = pole.shape.iter().map(|v| v.norm_sqr()).sum();
        let scale = if power > 0.0 {
            along / power
        } else {
            Complex::new(1.0, 0.0)
        };
        for (s, (v, r)) in squared.iter_mut().zip(pole.shape.iter().zip(&shape)) {
            *s += (v * scale - r).norm_sqr();
        }
    }
    let count = cluster.poles.len() as f64;
    IdentifiedMode {
        frequency,
        frequency_sd: sd(&frequencies),
        damping,
        damping_sd: sd(&dampings),
        mpc: representative.mpc,
        mpd: representative.mpd,
        shape,
        shape_sd: squared.iter().map(|s| (s / count).sqrt()).collect(),
        orders: cluster.poles.iter().map(|(o, _)| *o).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pole(frequency: f64, damping: f64, shape: &[f64]) -> Pole {
        let w = 2.0 * PI * frequency;
        let eigenvalue = Complex::new(-damping * w, w * (1.0 - damping * damping).sqrt());
        Pole::new(
            eigenvalue,
            shape.iter().map(|&v| Complex::new(v, 0.0)).collect(),
        )
    }

    /// Two modes present at every order from the third; a noise pole that wanders; a
    /// negatively damped pole that stays put: the selection finds the two modes only.
    #[test]
    fn stable_physical_clusters_are_the_modes() {
        let orders: Vec<ModelOrder> = (1..=10)
            .map(|k| {
                let jitter = 1e-4 * (k as f64).sin();
                let mut poles = vec![pole(
                    7.0 + 3.0 * k as f64,
                    0.3,
                    &[1.0, (k as f64).cos(), 0.2],
                )];
                if k >= 3 {
                    poles.push(pole(2.0 * (1.0 + jitter), 0.01, &[0.5, 1.0, 0.8]));
                    poles.push(pole(5.0, 0.02 * (1.0 + jitter), &[1.0, -0.4, -0.9]));
                    poles.push(pole(4.0, -0.01, &[1.0, 1.0, 1.0]));
                }
                ModelOrder {
                    order: 2 * k,
                    poles,
                }
            })
            .collect();
        let diagram =
            StabilisationDiagram::new(orders, StabilityTolerances::default()).expect("valid");
        assert!(!diagram.orders[0].poles[0].stable.frequency);
        assert!(diagram.orders[5].poles[1].stable.all());
        let modes = select_modes(&diagram, &SelectionOptions::default()).expect("valid");
        assert_eq!(modes.len(), 2, "{modes:?}");
        assert!((modes[0].frequency - 2.0).abs() < 1e-3);
        assert!((modes[1].damping - 0.02).abs() < 1e-5);
        // Stable from the fourth order (the third is the first with them): 7 of 10.
        assert_eq!(modes[0].orders.len(), 7);
        assert!(modes[0].mpc > 0.999 && modes[0].mpd < 1e-6);
        assert!(modes[0].shape_sd.iter().all(|s| *s < 1e-12));
    }

    /// A mode at the force's upper edge, one above the force's band and one whose shape is a
    /// single channel are set aside with their reasons; the others, and every mode when the
    /// force was not measured but for the one-channel shape, are kept.
    #[test]
    fn the_excitations_modes_and_one_channel_shapes_are_set_aside() {
        let mode = |frequency: f64, shape: &[f64]| IdentifiedMode {
            frequency,
            frequency_sd: 0.0,
            damping: 0.01,
            damping_sd: 0.0,
            shape: shape.iter().map(|&v| Complex::new(v, 0.0)).collect(),
            shape_sd: vec![0.0; shape.len()],
            mpc: 1.0,
            mpd: 0.0,
            orders: vec![],
        };
        let modes = vec![
            mode(3.0, &[0.5, 0.9, 1.0]),
            mode(9.0, &[1.0, 0.1, -0.2]),
            mode(12.0, &[1.0, -0.5, 0.8]),
            mode(39.0, &[1.0, 0.6, 0.3]),
            mode(60.0, &[0.2, 1.0, 0.4]),
        ];
        let options = ScreenOptions {
            excited: Some((0.5, 40.0)),
            edges: (true, true),
            ..ScreenOptions::default()
        };
        let (kept, rejected) = screen_modes(modes.clone(), &options);
        let frequencies = |m: &[IdentifiedMode]| m.iter().map(|m| m.frequency).collect::<Vec<_>>();
        assert_eq!(frequencies(&kept), vec![3.0, 12.0]);
        let why: Vec<(f64, Rejection)> = rejected
            .iter()
            .map(|r| (r.mode.frequency, r.rejection))
            .collect();
        assert_eq!(
            why,
            vec![
                (9.0, Rejection::OneChannel),
                (39.0, Rejection::ExcitationEdge),
                (60.0, Rejection::OutsideExcitation)
            ]
        );
        let (kept, _) = screen_modes(modes, &ScreenOptions::default());
        assert_eq!(frequencies(&kept), vec![3.0, 12.0, 39.0, 60.0]);
    }

    /// A resonance is a peak of its FRF; a flat stretch of noise, or a peak whose coherence
    /// is low, is not; of two modes closer than the resolution the one of more poles stands.
    #[test]
    fn modes_need_a_peak_and_a_resolvable_distance() {
        let frequencies: Vec<f64> = (0..400).map(|k| 0.1 * k as f64).collect();
        let resonance: Vec<f64> = frequencies
            .iter()
            .map(|f| {
                let r = f / 10.0;
                1.0 / ((1.0 - r * r).powi(2) + (0.02 * r).powi(2)).sqrt()
            })
            .collect();
        let flat = vec![1.0; frequencies.len()];
        let curves = [resonance, flat];
        let coherent = [vec![0.9; 400], vec![0.9; 400]];
        let evidence = PeakEvidence {
            frequencies: &frequencies,
            curves: &curves,
            coherence: Some(&coherent),
        };
        assert!(evidence.supports(10.0));
        assert!(!evidence.supports(25.0));
        let incoherent = [vec![0.3; 400], vec![0.9; 400]];
        let evidence = PeakEvidence {
            coherence: Some(&incoherent),
            ..evidence
        };
        assert!(!evidence.supports(10.0));
        let mode = |frequency: f64, poles: usize| IdentifiedMode {
            frequency,
            frequency_sd: 0.0,
            damping: 0.01,
            damping_sd: 0.0,
            shape: vec![Complex::new(1.0, 0.0), Complex::new(0.5, 0.0)],
            shape_sd: vec![0.0; 2],
            mpc: 1.0,
            mpd: 0.0,
            orders: (0..poles).collect(),
        };
        let options = ScreenOptions {
            resolution: Some(0.25),
            ..ScreenOptions::default()
        };
        let (kept, rejected) = screen_modes(vec![mode(9.0, 5), mode(9.1, 9)], &options);
        assert_eq!(kept.len(), 1);
        assert_eq!(kept[0].frequency, 9.1);
        assert_eq!(rejected[0].rejection, Rejection::Unresolved);
        // Beyond the resolution but within 1 % with the same shape: one resonance split by
        // the fit. With another shape, two modes.
        let (kept, rejected) = screen_modes(vec![mode(30.0, 5), mode(30.27, 9)], &options);
        assert_eq!(kept.len(), 1);
        assert_eq!(kept[0].frequency, 30.27);
        assert_eq!(rejected[0].rejection, Rejection::Unresolved);
        let mut other = mode(30.27, 9);
        other.shape = vec![Complex::new(0.5, 0.0), Complex::new(-1.0, 0.0)];
        let (kept, _) = screen_modes(vec![mode(30.0, 5), other], &options);
        assert_eq!(kept.len(), 2);
        // 2 % damped at 1.95 and 2.02 Hz (3.6 % apart, 0.07 Hz within their half-power
        // half-widths' 0.079 Hz), the same shape: one hump, one resonance. At 1 % damping
        // (0.039 Hz) they are two peaks.
        let damped = |frequency: f64, poles: usize, damping: f64| IdentifiedMode {
            damping,
            ..mode(frequency, poles)
        };
        let (kept, rejected) = screen_modes(
            vec![damped(1.95, 9, 0.02), damped(2.02, 5, 0.02)],
            &ScreenOptions::default(),
        );
        assert_eq!((kept.len(), kept[0].frequency), (1, 1.95));
        assert_eq!(rejected[0].rejection, Rejection::Unresolved);
        let (kept, _) = screen_modes(
            vec![damped(1.95, 9, 0.01), damped(2.02, 5, 0.01)],
            &ScreenOptions::default(),
        );
        assert_eq!(kept.len(), 2);
    }

    #[test]
    fn bad_options_are_named() {
        let options = SelectionOptions {
            max_mpd: 120.0,
            ..SelectionOptions::default()
        };
        let err = options.validate().expect_err("out of range");
        assert!(err.to_string().contains("MPD"), "{err}");
    }
}
