//! What a corrector corrects: its measured channels (any set of `acc<i>`, `vel<i>`, `disp<i>`)
//! and the excitation it is given (`force` or `ground_acc`), and which of them each channel's GP
//! takes as inputs.
//!
//! The paper's rig (acc1, acc2, acc3 and the force) is the default: its variables, value
//! references and training file are those the corrector always had. Another layout is read at
//! `fmi2Instantiate` from the bundled training file (its `channels` and `excitation`), and gets
//! a variable table of its own ([`crate::variables::table`]).
//!
//! **The inputs of a channel's GP** ([`Layout::columns_of`]): lags of the physics prediction of
//! the channel itself and of at most [`NEIGHBOURS`] other measured channels, the nearest by floor
//! (ties: same quantity first, then the lower floor), and of the excitation; so at most
//! `(NEIGHBOURS + 2)(q + 1)` inputs, 40 at the default q = 9, however many storeys and channels
//! the building has. Why: a Matérn ARD GP fits one length scale per input by type-II maximum
//! likelihood, each gradient `O(n² D)` on top of the `O(n³)` factorisation, and beyond about 40
//! inputs the likelihood surface gets flat in most of them (fits slow and land badly); and in a
//! shear building a floor's discrepancy (a storey's unmodelled force) acts through the storeys
//! next to it, which the nearest floors' predictions see, while the excitation drives them all.
//! On the paper's rig every GP takes all three floors and the force, as before.

use serde::{Deserialize, Serialize};
use structure::channel::{Channel, ExcitationKind, Quantity};
use structure::MAX_STOREYS;

/// How many other measured channels a channel's GP takes besides its own.
pub const NEIGHBOURS: usize = 2;

/// The corrector's channels and excitation.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Layout {
    /// The measured channels, in the corrector's order: accelerations, velocities,
    /// displacements, each by floor ([`Layout::checked`]).
    pub channels: Vec<Channel>,
    pub excitation: ExcitationKind,
}

impl Default for Layout {
    /// The paper's rig: acc1, acc2, acc3 and the force ([`structure::paper`]).
    fn default() -> Self {
        Layout {
            channels: structure::paper::channels(),
            excitation: ExcitationKind::of(&structure::paper::EXCITATION),
        }
    }
}

fn rank(c: &Channel) -> (usize, usize) {
    match *c {
        Channel::Response { quantity, floor } => (
            match quantity {
                Quantity::Acceleration => 0,
                Quantity::Velocity => 1,
                _ => 2,
            },
            floor,
        ),
        _ => (3, 0),
    }
}

fn floor_of(c: &Channel) -> usize {
    match *c {
        Channel::Response { floor, .. } => floor,
        _ => 0,
    }
}

impl Layout {
    /// A layout from channel names (`acc1`, `vel3`) and the excitation's (`force`,
    /// `ground_acc`), checked.
    pub fn from_names<S: AsRef<str>>(channels: &[S], excitation: &str) -> Result<Layout, String> {
        let channels = channels
            .iter()
            .map(|n| {
                let n = n.as_ref();
                Channel::parse(n)
                    .filter(|c| matches!(c, Channel::Response { .. }))
                    .ok_or_else(|| format!("channel '{n}' is not acc<i>, vel<i> or disp<i>"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let excitation = match Channel::parse(excitation) {
            Some(Channel::Excitation(kind)) => kind,
            _ => {
                return Err(format!(
                    "excitation '{excitation}' is neither 'force' nor 'ground_acc'"
                ))
            }
        };
        Layout {
            channels,
            excitation,
        }
        .checked()
    }

    /// Checked and in the corrector's order: at least one channel, each a response of a floor
    /// 1..=[`MAX_STOREYS`] named once.
    pub fn checked(mut self) -> Result<Layout, String> {
        if self.channels.is_empty() {
            return Err("no measured channel: a corrector needs at least one".into());
        }
        for c in &self.channels {
            match *c {
                Channel::Response { quantity, floor }
                    if matches!(
                        quantity,
                        Quantity::Acceleration | Quantity::Velocity | Quantity::Displacement
                    ) && (1..=MAX_STOREYS).contains(&floor) => {}
                _ => {
                    return Err(format!(
                    "channel '{}' is not acc<i>, vel<i> or disp<i> of a floor 1 to {MAX_STOREYS}",
                    c.name()
                ))
                }
            }
        }
        self.channels.sort_by_key(rank);
        if let Some(w) = self.channels.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("channel '{}' is named twice", w[0].name()));
        }
        Ok(self)
    }

    /// The paper's rig (its variables are those of `modelDescription/fmu_gp_corrector.xml`).
    pub fn is_paper(&self) -> bool {
        *self == Layout::default()
    }

    /// The measured channels' names, in order.
    pub fn names(&self) -> Vec<String> {
        self.channels.iter().map(Channel::name).collect()
    }

    /// The excitation's name: `force` or `ground_acc`.
    pub fn excitation_name(&self) -> String {
        Channel::Excitation(self.excitation).name()
    }

    /// The index of `channel` among the measured ones.
    pub fn index_of(&self, channel: Channel) -> Option<usize> {
        self.channels.iter().position(|&c| c == channel)
    }

    /// Values in one sample: the physics prediction of every channel, then the excitation.
    pub fn sample_width(&self) -> usize {
        self.channels.len() + 1
    }

    /// The sample's columns channel `j`'s GP takes (rule in the module documentation), in the
    /// sample's order: the chosen channels', then the excitation's (the last column).
    pub fn columns_of(&self, j: usize) -> Vec<usize> {
        let own = self.channels[j];
        let mut others: Vec<usize> = (0..self.channels.len()).filter(|&i| i != j).collect();
        others.sort_by_key(|&i| {
            let c = self.channels[i];
            (
                floor_of(&c).abs_diff(floor_of(&own)),
                usize::from(c.quantity() != own.quantity()),
                rank(&c),
            )
        });
        let mut chosen: Vec<usize> = std::iter::once(j)
            .chain(others.into_iter().take(NEIGHBOURS))
            .collect();
        chosen.sort_unstable();
        chosen.push(self.channels.len());
        chosen
    }

    /// The input dimension of channel `j`'s GP at `lags` lags.
    pub fn input_dimension_of(&self, j: usize, lags: usize) -> usize {
        self.columns_of(j).len() * (lags + 1)
    }
}

/// Channel `j`'s GP input from the whole lag vector `x` of a sample ([`crate::lags`]: column by
/// column, `lags + 1` values each): the blocks of `columns`, in order.
pub fn select(x: &[f64], columns: &[usize], lags: usize) -> Vec<f64> {
    let block = lags + 1;
    let mut out = Vec::with_capacity(columns.len() * block);
    for &c in columns {
        out.extend_from_slice(&x[c * block..(c + 1) * block]);
    }
    out
}

/// The names a layout's outputs of channel `c` take: the corrected value is the channel's name;
/// the latent variance and the predictive sd of an acceleration `acc<i>` are `latent_var<i>` and
/// `sd<i>` (the paper rig's names), of another channel `latent_var_<name>` and `sd_<name>`.
pub fn band_name(prefix: &str, c: &Channel) -> String {
    match *c {
        Channel::Response {
            quantity: Quantity::Acceleration,
            floor,
        } => format!("{prefix}{floor}"),
        _ => format!("{prefix}_{}", c.name()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(names: &[&str], excitation: &str) -> Layout {
        Layout::from_names(names, excitation).expect("a layout")
    }

    #[test]
    fn the_paper_rig_gives_every_gp_all_three_floors_and_the_force() {
        let rig = layout(&["acc3", "acc1", "acc2"], "force");
        assert!(rig.is_paper());
        for j in 0..3 {
            assert_eq!(rig.columns_of(j), vec![0, 1, 2, 3]);
            assert_eq!(rig.input_dimension_of(j, 9), 40);
        }
    }

    #[test]
    fn the_inputs_stay_bounded_on_a_tall_building() {
        let names: Vec<String> = (1..=20)
            .flat_map(|f| [format!("acc{f}"), format!("disp{f}")])
            .collect();
        let tall = Layout::from_names(&names, "ground_acc").expect("a layout");
        assert_eq!(tall.sample_width(), 41);
        for j in 0..tall.channels.len() {
            assert!(tall.input_dimension_of(j, 9) <= 40);
        }
        // acc7: itself, disp7 (same floor), then acc6 (the same quantity, lower floor first).
        let acc7 = tall
            .index_of(Channel::parse("acc7").expect("test value"))
            .expect("test value");
        let names_of = |cols: Vec<usize>| -> Vec<String> {
            cols.iter()
                .map(|&c| {
                    tall.channels
                        .get(c)
                        .map_or("ground_acc".into(), Channel::name)
                })
                .collect()
        };
        assert_eq!(
            names_of(tall.columns_of(acc7)),
            ["acc6", "acc7", "disp7", "ground_acc"]
        );
        // A sparse set: acc1's nearest are acc3 and acc5.
        let sparse = layout(&["acc5", "acc1", "acc3", "acc9"], "force");
        assert_eq!(sparse.columns_of(0), vec![0, 1, 2, 4]);
        assert_eq!(sparse.columns_of(3), vec![1, 2, 3, 4]);
        assert_eq!(layout(&["vel2"], "force").columns_of(0), vec![0, 1]);
    }

    #[test]
    fn bad_layouts_are_refused_by_name() {
        for (names, excitation, needle) in [
            (vec![], "force", "no measured channel"),
            (vec!["acc1", "acc1"], "force", "'acc1' is named twice"),
            (vec!["force"], "force", "'force' is not"),
            (vec!["acc51"], "force", "'acc51'"),
            (vec!["acc1"], "time", "excitation 'time'"),
        ] {
            let e = Layout::from_names(&names, excitation).expect_err(needle);
            assert!(e.contains(needle), "{e}");
        }
    }

    #[test]
    fn a_selection_takes_the_columns_blocks() {
        let x: Vec<f64> = (0..12).map(f64::from).collect();
        assert_eq!(select(&x, &[0, 2], 2), vec![0.0, 1.0, 2.0, 6.0, 7.0, 8.0]);
        let acc = Channel::parse("acc2").expect("test value");
        let vel = Channel::parse("vel4").expect("test value");
        assert_eq!(band_name("latent_var", &acc), "latent_var2");
        assert_eq!(band_name("sd", &vel), "sd_vel4");
    }
}
