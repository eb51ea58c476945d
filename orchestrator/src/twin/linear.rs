//! The twin's physics as the linear shear model it instantiates, run in process over a whole
//! record (`fmu_shear::batch`): the same step maps as a run of its FMU through FMI, in blocks of
//! samples. Used where the linear model's derivatives are wanted over many samples (the band
//! of `twin compare`, a calibration's Jacobian), and only when the twin is exactly that model:
//! its physics alone, every effect off, no control force, accelerometers.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use ::structure::channel::{Channel, Quantity};
use fmi2::CoSimModel;
use fmu_shear::batch::{accelerations_along, LinearRecord};
use fmu_shear::modal::{band, normals, Modal, Normals};
use fmu_shear::{ShearModel, ShearParameters, StructureResource};
use nalgebra::DMatrix;

use super::data::Measurement;
use super::{ParameterValue, Twin, PHYSICS};

/// The structure file inside the shear FMU.
const RESOURCE: &str = "resources/structure.json";

/// The shear parameters the twin's physics FMU runs with — its `resources/structure.json` (the
/// paper's rig without one) with the twin's parameter values applied as `fmi2SetReal` would —
/// when that is the linear model alone: None for a twin with other components, an FMU that is
/// not the shear model (its modelDescription's GUID not the shear model's for that structure),
/// a value it refuses, or an effect switched on.
pub fn linear_shear(twin: &Twin) -> Option<ShearParameters> {
    if twin.components.len() != 1 {
        return None;
    }
    let physics = twin.component(PHYSICS)?;
    linear_shear_of(&physics.fmu_path, &physics.parameters)
}

/// [`linear_shear`] of one FMU archive with its parameter values.
fn linear_shear_of(
    fmu: &Path,
    parameters: &BTreeMap<String, ParameterValue>,
) -> Option<ShearParameters> {
    let (resource, guid) = shear_archive(fmu)?;
    let params = resource.parameters().ok()?;
    let mut model = ShearModel::for_parameters(params);
    let info = model.table();
    // The shear model's own description of that structure, or another FMU.
    if guid != info.guid {
        return None;
    }
    for (name, value) in parameters {
        let vr = info.by_name(name)?.vr;
        match *value {
            ParameterValue::Real(x) => model.set_real(vr, x).ok()?,
            ParameterValue::Integer(i) => model.set_integer(vr, i).ok()?,
            ParameterValue::Boolean(b) => model.set_boolean(vr, b).ok()?,
        }
    }
    // A run from a given state is the FMU's (the in-process pass starts at rest).
    (!model.effects.any_enabled() && model.starts_at_rest()).then_some(model.params)
}

/// A calibration of the linear shear model's `m`, `c`, `k` on accelerometers, in process: the
/// residuals' predictions and their Jacobian from one pass over each record (`fmu_shear::batch`,
/// the FMU's own step and derivative maps), where through FMI a run steps and reads them one
/// sample at a time.
pub struct LinearFit {
    params: ShearParameters,
    /// Each calibrated parameter's place in `m1..mN, c1..cN, k1..kN`.
    index: Vec<usize>,
    /// The unit direction of each calibrated parameter (3N × p).
    directions: DMatrix<f64>,
}

impl LinearFit {
    /// For the FMU archive `fmu` with the twin's values `base`, calibrating `names`: None
    /// unless that is the linear shear model ([`linear_shear`]) and every name one of its
    /// `m`, `c`, `k`.
    pub fn new(
        fmu: &Path,
        base: &BTreeMap<String, ParameterValue>,
        names: &[String],
    ) -> Option<LinearFit> {
        let params = linear_shear_of(fmu, base)?;
        let n = params.storeys();
        let index: Vec<usize> = names
            .iter()
            .map(|name| parameter_index(name, n))
            .collect::<Option<_>>()?;
        let mut directions = DMatrix::zeros(3 * n, index.len());
        for (a, &j) in index.iter().enumerate() {
            directions[(j, a)] = 1.0;
        }
        Some(LinearFit {
            params,
            index,
            directions,
        })
    }

    /// The floors (0-based) of `channels` (`acc<i>` names), None for any other channel or a
    /// floor the structure lacks.
    pub fn floors(&self, channels: &[&str]) -> Option<Vec<usize>> {
        let n = self.params.storeys();
        channels
            .iter()
            .map(|name| match Channel::parse(name)? {
                Channel::Response {
                    quantity: Quantity::Acceleration,
                    floor,
                } if (1..=n).contains(&floor) => Some(floor - 1),
                _ => None,
            })
            .collect()
    }

    /// The structure's parameters with the calibrated ones at `values`; None for a value the
    /// FMU's setters refuse.
    fn at(&self, values: &[f64]) -> Option<ShearParameters> {
        let n = self.params.storeys();
        let mut params = self.params.clone();
        for (&j, &v) in self.index.iter().zip(values) {
            let (group, i) = (j / n, j % n);
            // As the FMU's setters: a mass > 0, a damping or stiffness ≥ 0 (NaN neither).
            if !(v > 0.0 || (group > 0 && v >= 0.0)) {
                return None;
            }
            [&mut params.mass, &mut params.damping, &mut params.stiffness][group][i] = v;
        }
        Some(params)
    }

    /// Run the model with the calibrated parameters at `values` over `data`, measuring
    /// `floors`: `each(k, predictions, derivatives)`, `derivatives[slot · p + j]` along
    /// calibrated parameter j. None for a value the FMU's setters refuse.
    pub fn run(
        &self,
        values: &[f64],
        data: &Measurement,
        floors: &[usize],
        each: impl FnMut(usize, &[f64], &[f64]),
    ) -> Option<()> {
        let params = self.at(values)?;
        let record = LinearRecord {
            dt: data.dt,
            excitation: &data.excitation.values,
            floors,
        };
        accelerations_along(&params, &record, &self.directions, each);
        Some(())
    }

    /// The model with the calibrated parameters at `values` over `data`, through its modes
    /// (`fmu_shear::modal`): each of `floors`' predictions at every sample, and over the `used`
    /// samples its `Σ ∂ŷ ∂ŷᵀ` and `Σ ∂ŷ (y − ŷ)` along the calibrated parameters, `measured`
    /// the floors' records. None for a value the FMU's setters refuse, or a structure whose
    /// modes are not distinct (then [`LinearFit::run`] gives the derivatives).
    pub fn normals(
        &self,
        values: &[f64],
        data: &Measurement,
        floors: &[usize],
        measured: &[&[f64]],
        used: &[usize],
    ) -> Option<Normals> {
        let params = self.at(values)?;
        let modal = Modal::new(&params, data.dt, floors, &self.directions)?;
        let record = LinearRecord {
            dt: data.dt,
            excitation: &data.excitation.values,
            floors,
        };
        let out = normals(&modal, &record, measured, used);
        let finite = out
            .blocks
            .iter()
            .all(|(a, g)| a.iter().chain(g.iter()).all(|x| x.is_finite()))
            && out.predictions.iter().flatten().all(|x| x.is_finite());
        finite.then_some(out)
    }
}

/// `resources/structure.json` of an FMU archive (the paper's rig when it has none) and its
/// `modelDescription.xml`; None when either cannot be read.
fn shear_archive(fmu: &Path) -> Option<(StructureResource, String)> {
    let mut archive = zip::ZipArchive::new(std::fs::File::open(fmu).ok()?).ok()?;
    let guid = description_guid(archive.by_name("modelDescription.xml").ok()?)?;
    let mut text = String::new();
    let resource = match archive.by_name(RESOURCE) {
        Ok(mut entry) => {
            entry.read_to_string(&mut text).ok()?;
            serde_json::from_str(&text).ok()?
        }
        Err(zip::result::ZipError::FileNotFound) => StructureResource {
            structure: ::structure::Structure::default(),
            control_floor: 1,
        },
        Err(_) => return None,
    };
    Some((resource, guid))
}

/// The `guid` of a modelDescription's root element, read up to that element only (a 20-storey
/// shear model's description is 621 kB; its root is in the first few hundred bytes).
fn description_guid(description: impl Read) -> Option<String> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_reader(std::io::BufReader::new(description));
    let mut buf = Vec::new();
    loop {
        match reader.read_event_into(&mut buf).ok()? {
            Event::Start(e) | Event::Empty(e) => {
                if e.name().as_ref() != b"fmiModelDescription" {
                    return None;
                }
                let guid = e.try_get_attribute("guid").ok()??;
                return Some(guid.unescape_value().ok()?.into_owned());
            }
            Event::Eof => return None,
            _ => buf.clear(),
        }
    }
}

/// The index of `name` among `m1..mN, c1..cN, k1..kN` (the sensitivities' order).
fn parameter_index(name: &str, storeys: usize) -> Option<usize> {
    let group = ["m", "c", "k"].iter().position(|g| name.starts_with(g))?;
    let floor: usize = name[1..].parse().ok()?;
    (1..=storeys)
        .contains(&floor)
        .then_some(group * storeys + floor - 1)
}

/// The band's variance `diag(J Σ Jᵀ)` per measured channel (the record's order) and sample, `J`
/// the accelerations' derivatives along the parameters `names` (Σ's order) taken in process
/// along the rows of `root` (`Σ = Rᵀ R`, so the variance is `Σᵢ (J rᵢ)²`). None unless the twin
/// is the linear shear model ([`linear_shear`]), the record has no control column and measures
/// accelerations only, and every name is one of its `m`, `c`, `k`.
pub fn acceleration_band(
    twin: &Twin,
    data: &Measurement,
    names: &[String],
    root: &DMatrix<f64>,
) -> Option<Vec<Vec<f64>>> {
    if data.extra.contains_key("control") {
        return None;
    }
    let params = linear_shear(twin)?;
    let n = params.storeys();
    let floors: Vec<usize> = data
        .responses
        .iter()
        .map(|s| match s.channel {
            Channel::Response {
                quantity: Quantity::Acceleration,
                floor,
            } if (1..=n).contains(&floor) => Some(floor - 1),
            _ => None,
        })
        .collect::<Option<_>>()?;
    let index: Vec<usize> = names
        .iter()
        .map(|name| parameter_index(name, n))
        .collect::<Option<_>>()?;
    // Direction r (a row of R) in the 3N parameters: R's row spread over the named ones.
    let d = root.nrows();
    let mut directions = DMatrix::zeros(3 * n, d);
    for (a, &j) in index.iter().enumerate() {
        for r in 0..d {
            directions[(j, r)] += root[(r, a)];
        }
    }
    let record = LinearRecord {
        dt: data.dt,
        excitation: &data.excitation.values,
        floors: &floors,
    };
    // Through the modes (one product a block), else the sensitivity state in groups.
    if let Some(modal) = Modal::new(&params, data.dt, &floors, &directions) {
        let band = band_on_threads(&modal, &record);
        if band.iter().flatten().all(|v| v.is_finite()) {
            return Some(band);
        }
    }
    band_in_groups(&params, &record, &directions)
}

/// The band through the modes with the measured slots shared among the cores, each group a
/// pass of its own over the record (the modes' recursion, a small part of the work, repeated):
/// every slot's variance is computed as in one pass, to the bit.
fn band_on_threads(modal: &Modal, record: &LinearRecord) -> Vec<Vec<f64>> {
    let slots = modal.coefficients();
    let threads = crate::parallel::cores();
    let groups: Vec<&[DMatrix<f64>]> = slots.chunks(slots.len().div_ceil(threads).max(1)).collect();
    crate::parallel::on_threads(&groups, threads, |group| band(modal, record, group))
        .into_iter()
        .flatten()
        .collect()
}

/// Directions a pass of [`band_in_groups`] takes at most: up to ten storeys (30 parameters)
/// the band is one pass; at twenty (60), two.
const BAND_GROUP: usize = 32;

/// [`band_along`] over the columns of `directions` in groups of at most [`BAND_GROUP`], each
/// group a pass of its own over the record (its state stepped again: 4N² a step against the
/// group's ~8N² per direction), the groups over the cores; their sums added in the groups'
/// order, so the band is the same on any number of cores.
fn band_in_groups(
    params: &ShearParameters,
    record: &LinearRecord,
    directions: &DMatrix<f64>,
) -> Option<Vec<Vec<f64>>> {
    let d = directions.ncols();
    let groups: Vec<DMatrix<f64>> = (0..d.div_ceil(BAND_GROUP))
        .map(|g| {
            let (first, end) = (g * BAND_GROUP, ((g + 1) * BAND_GROUP).min(d));
            directions.columns(first, end - first).into_owned()
        })
        .collect();
    let threads = crate::parallel::cores();
    let parts =
        crate::parallel::on_threads(&groups, threads, |group| band_along(params, record, group));
    let mut band: Option<Vec<Vec<f64>>> = None;
    for part in parts {
        let part = part?;
        match &mut band {
            None => band = Some(part),
            Some(sum) => {
                for (b, p) in sum.iter_mut().zip(&part) {
                    for (x, y) in b.iter_mut().zip(p) {
                        *x += y;
                    }
                }
            }
        }
    }
    band
}

/// `Σᵢ (J rᵢ)²` over the columns `rᵢ` of `directions` per measured floor and sample, from one
/// in-process pass; None when a value is not finite.
fn band_along(
    params: &ShearParameters,
    record: &LinearRecord,
    directions: &DMatrix<f64>,
) -> Option<Vec<Vec<f64>>> {
    let d = directions.ncols();
    let samples = record.excitation.len();
    let mut band: Vec<Vec<f64>> = vec![Vec::with_capacity(samples); record.floors.len()];
    let mut finite = true;
    accelerations_along(params, record, directions, |_, _, derivatives| {
        for (c, b) in band.iter_mut().enumerate() {
            let v: f64 = derivatives[c * d..(c + 1) * d].iter().map(|x| x * x).sum();
            finite &= v.is_finite();
            b.push(v);
        }
    });
    finite.then_some(band)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The root's guid, read without the rest; anything else at the root is not a description.
    #[test]
    fn the_guid_is_read_from_the_root_alone() {
        let xml = "<?xml version=\"1.0\"?>\n<!-- c -->\n<fmiModelDescription fmiVersion=\"2.0\" \
                   guid=\"{a&amp;b}\"><ModelVariables>";
        assert_eq!(description_guid(xml.as_bytes()).as_deref(), Some("{a&b}"));
        assert_eq!(description_guid("<other guid=\"{x}\"/>".as_bytes()), None);
        assert_eq!(description_guid("<fmiModelDescription/>".as_bytes()), None);
        assert_eq!(description_guid("".as_bytes()), None);
    }

    /// The default twin's FMU is the linear shear model; the same archive with another GUID in
    /// its description is not taken for it.
    #[test]
    fn the_shear_fmu_is_recognised_by_its_guid() {
        let twin = Twin::default_twin().expect("the default twin");
        assert!(
            linear_shear(&twin).is_some(),
            "the default twin is the linear model"
        );
        let physics = twin.component(PHYSICS).expect("physics");
        let dir = tempfile::tempdir().expect("temporary directory");
        let altered = dir.path().join("altered.fmu");
        let mut source =
            zip::ZipArchive::new(std::fs::File::open(&physics.fmu_path).expect("open"))
                .expect("an archive");
        let mut out = zip::ZipWriter::new(std::fs::File::create(&altered).expect("create"));
        for i in 0..source.len() {
            let mut entry = source.by_index(i).expect("entry");
            let name = entry.name().to_owned();
            let mut bytes = Vec::new();
            entry.read_to_end(&mut bytes).expect("read");
            if name == "modelDescription.xml" {
                let text = String::from_utf8(bytes).expect("UTF-8");
                let at = text.find("guid=\"{").expect("a guid") + 7;
                let other = if &text[at..=at] == "0" { "1" } else { "0" };
                bytes = format!("{}{other}{}", &text[..at], &text[at + 1..]).into_bytes();
            }
            out.start_file(name, zip::write::SimpleFileOptions::default())
                .expect("start");
            std::io::Write::write_all(&mut out, &bytes).expect("write");
        }
        out.finish().expect("finish");
        assert!(linear_shear_of(&altered, &physics.parameters).is_none());
    }

    /// Twelve storeys, 36 directions (two groups): the band in groups is the band of one pass
    /// to rounding (the sums only added in another order; bar 1e-12 of each sample's value).
    #[test]
    fn the_band_in_groups_is_the_band_of_one_pass() {
        let n = 12;
        let structure = ::structure::Structure {
            mass: (0..n).map(|i| 4.0 + 0.1 * i as f64).collect(),
            damping: (0..n).map(|i| 2.0 + 0.3 * (i % 4) as f64).collect(),
            stiffness: (0..n).map(|i| 4000.0 - 50.0 * i as f64).collect(),
            excitation: ::structure::Excitation::Force { floor: 2 },
        };
        let params = ShearParameters::from_structure(&structure);
        let excitation: Vec<f64> = (0..900)
            .map(|k| (0.37 * k as f64).sin() + 0.5 * (1.3 * k as f64).cos())
            .collect();
        let floors = [0, 5, 11];
        let record = LinearRecord {
            dt: 1.0 / 100.0,
            excitation: &excitation,
            floors: &floors,
        };
        let d = 3 * n;
        assert!(d > BAND_GROUP, "more than one group");
        let directions =
            DMatrix::from_fn(3 * n, d, |j, a| ((j * 7 + a * 5) % 11) as f64 / 11.0 - 0.4);
        let grouped = band_in_groups(&params, &record, &directions).expect("finite");
        let whole = band_along(&params, &record, &directions).expect("finite");
        let mut worst = 0.0f64;
        for (g, w) in grouped.iter().zip(&whole) {
            assert_eq!(g.len(), excitation.len());
            for (a, b) in g.iter().zip(w) {
                worst = worst.max((a - b).abs() / b.abs().max(f64::MIN_POSITIVE));
            }
        }
        assert!(whole[2].iter().any(|&v| v > 0.0), "the band is not empty");
        assert!(worst <= 1e-12, "grouped against one pass: {worst:e}");
    }
}
