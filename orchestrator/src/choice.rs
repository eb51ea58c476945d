//! Options with a closed set of values (the master algorithm, a hybrid test's coupling, …),
//! each value named as the command line and the Python package spell it, with a line of help.
//! The library names them; `twin`'s parser and the Python package read them from here.

/// A closed set of values, by name.
pub trait Choice: Copy + PartialEq + 'static {
    /// Every value: its name, a line of help, the value.
    const CHOICES: &'static [(&'static str, &'static str, Self)];

    /// The value called `name` (exactly; names are lower case).
    fn from_name(name: &str) -> Option<Self> {
        Self::CHOICES
            .iter()
            .find(|(n, _, _)| *n == name)
            .map(|&(_, _, value)| value)
    }

    /// This value's name.
    fn choice_name(self) -> &'static str {
        Self::CHOICES
            .iter()
            .find(|(_, _, value)| *value == self)
            .map(|(name, _, _)| *name)
            .expect("every value of a choice is listed in CHOICES")
    }

    /// Every name, in order.
    fn names() -> Vec<&'static str> {
        Self::CHOICES.iter().map(|(name, _, _)| *name).collect()
    }
}

impl Choice for fmu_gp_corrector::TargetForm {
    const CHOICES: &'static [(&'static str, &'static str, Self)] = &[
        (
            "discrepancy",
            "the GP models measured − physics; corrected = physics + GP mean",
            fmu_gp_corrector::TargetForm::Discrepancy,
        ),
        (
            "measured",
            "the GP models the measured acceleration itself; corrected = GP mean",
            fmu_gp_corrector::TargetForm::Measured,
        ),
    ];
}

/// `Display` as the value's name (what clap shows as a default).
macro_rules! display_by_name {
    ($($ty:ty),* $(,)?) => {$(
        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str($crate::choice::Choice::choice_name(*self))
            }
        }
    )*};
}
pub(crate) use display_by_name;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cosim::master::Algorithm;
    use crate::workflows::control::design::StateUnit;
    use crate::workflows::control::EstimatorChoice;
    use crate::workflows::hybrid::experiment::Coupling;

    fn round_trip<T: Choice + std::fmt::Debug>(expected: &[&str]) {
        assert_eq!(T::names(), expected);
        for &(name, help, value) in T::CHOICES {
            assert_eq!(T::from_name(name), Some(value), "{name}");
            assert_eq!(value.choice_name(), name);
            assert!(!help.is_empty(), "{name} has no help");
        }
        assert_eq!(T::from_name("no-such-value"), None);
    }

    /// The names are the ones the command line took before they moved here (clap's kebab-case
    /// of the variants), so no script breaks.
    #[test]
    fn every_choice_names_its_values_once() {
        round_trip::<Algorithm>(&["gauss-seidel", "jacobi"]);
        round_trip::<Coupling>(&["auto", "monolithic", "stepped"]);
        round_trip::<StateUnit>(&["m", "mm"]);
        round_trip::<EstimatorChoice>(&["integrate", "kalman"]);
        round_trip::<fmu_gp_corrector::TargetForm>(&["discrepancy", "measured"]);
        assert_eq!(Algorithm::GaussSeidel.to_string(), "gauss-seidel");
    }
}
