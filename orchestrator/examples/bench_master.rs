//! In-process timings of what `twin compare` does with the shear FMU, for
//! scripts/bench-compare.sh: the FMU load alone, the master's run alone (the FMU already
//! loaded), the same steps driven through the FMU directly without the master, and `run_twin`
//! whole. Prints one JSON object of medians (seconds) to stdout.
//!
//!   cargo run --release -p orchestrator --example bench_master -- [--data D.csv] [--repetitions N]
//!
//! The FMU is the default twin's (`TWIN_FMU_DIR`, else the one built into the binary).

use std::time::Instant;

use anyhow::{bail, Context, Result};
use orchestrator::data::Measurement;
use orchestrator::import::Fmu;
use orchestrator::master::{Clock, Port, Recorder, System};
use orchestrator::run::run_twin;
use orchestrator::twin::{Twin, PHYSICS};

const OUTPUTS: [&str; 3] = ["acc1", "acc2", "acc3"];

fn median(mut samples: Vec<f64>) -> f64 {
    samples.sort_by(f64::total_cmp);
    let n = samples.len();
    if n % 2 == 1 {
        samples[n / 2]
    } else {
        0.5 * (samples[n / 2 - 1] + samples[n / 2])
    }
}

fn time<T>(repetitions: usize, mut work: impl FnMut() -> Result<T>) -> Result<f64> {
    let mut samples = Vec::with_capacity(repetitions);
    // One run before timing: page cache, lazy symbol binding.
    work()?;
    for _ in 0..repetitions {
        let start = Instant::now();
        std::hint::black_box(work()?);
        samples.push(start.elapsed().as_secs_f64());
    }
    Ok(median(samples))
}

/// The master's part of a run: instantiate and initialise, the system with the force replayed
/// (first-order hold) and the accelerations recorded, 1023 steps.
fn master_run(fmu: &Fmu, data: &Measurement) -> Result<Vec<f64>> {
    let mut instance = fmu.instantiate(PHYSICS)?;
    instance.setup_experiment(data.time[0], None)?;
    instance.enter_initialization_mode()?;
    instance.exit_initialization_mode()?;
    let outputs = OUTPUTS
        .iter()
        .map(|n| fmu.value_reference(n))
        .collect::<Result<Vec<_>, _>>()?;
    let mut system = System::new();
    let node = system.add_slave(
        PHYSICS,
        Box::new(instance),
        vec![fmu.value_reference("force")?],
        outputs,
    );
    let force = system.add_signal("force", data.force().to_vec());
    system.connect(force, node, 0)?;
    let mut recorder = Recorder::new(
        OUTPUTS
            .iter()
            .enumerate()
            .map(|(i, n)| (n.to_string(), Port::Output(node, i)))
            .collect(),
    );
    system.run(
        Clock::new(data.time[0], data.dt, (data.len() - 1) as u64),
        &mut [&mut recorder],
        |_, _| {},
    )?;
    Ok(std::mem::take(&mut recorder.columns[0]))
}

/// The same calls without the master: set force and slope, read, step.
fn direct_run(fmu: &Fmu, data: &Measurement) -> Result<Vec<f64>> {
    let mut instance = fmu.instantiate(PHYSICS)?;
    instance.setup_experiment(data.time[0], None)?;
    instance.enter_initialization_mode()?;
    instance.exit_initialization_mode()?;
    let force = [fmu.value_reference("force")?];
    let outputs = OUTPUTS
        .iter()
        .map(|n| fmu.value_reference(n))
        .collect::<Result<Vec<_>, _>>()?;
    let n = data.len();
    let mut acc1 = Vec::with_capacity(n);
    let mut out = [0.0; 3];
    for k in 0..n {
        instance.set_real(&force, &[data.force()[k]])?;
        if k + 1 < n {
            instance.set_real_input_derivatives(
                &force,
                &[(data.force()[k + 1] - data.force()[k]) / data.dt],
            )?;
        }
        instance.get_real(&outputs, &mut out)?;
        acc1.push(out[0]);
        if k + 1 < n {
            instance.do_step(data.time[0] + k as f64 * data.dt, data.dt)?;
        }
    }
    Ok(acc1)
}

fn main() -> Result<()> {
    let mut data_path = std::path::PathBuf::from("data/dataset1.csv");
    let mut repetitions = 31usize;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--data" => data_path = args.next().context("--data needs a file")?.into(),
            "--repetitions" => {
                repetitions = args
                    .next()
                    .context("--repetitions needs a number")?
                    .parse()?
            }
            other => bail!("unknown argument '{other}' (expected --data FILE, --repetitions N)"),
        }
    }
    if repetitions == 0 {
        bail!("--repetitions must be at least 1");
    }
    let data = Measurement::read(&data_path)?;
    let twin = Twin::default_twin()?;
    let fmu_path = twin
        .component(PHYSICS)
        .context("the default twin has a physics component")?
        .fmu_path
        .clone();

    let load = time(repetitions, || Ok(Fmu::open(&fmu_path)?))?;
    let fmu = Fmu::open(&fmu_path)?;
    // The master and the direct loop must compute the same thing, or the comparison means nothing.
    let (by_master, direct) = (master_run(&fmu, &data)?, direct_run(&fmu, &data)?);
    if by_master != direct {
        bail!("the master's run and the direct run differ");
    }
    let master = time(repetitions, || master_run(&fmu, &data))?;
    let direct = time(repetitions, || direct_run(&fmu, &data))?;
    let whole = time(repetitions, || Ok(run_twin(&twin, &data, |_, _| {})?))?;
    println!(
        "{{\"repetitions\": {repetitions}, \"steps\": {}, \"fmu_load_s\": {load:e}, \"master_run_s\": {master:e}, \"direct_run_s\": {direct:e}, \"run_twin_s\": {whole:e}}}",
        data.len() - 1
    );
    Ok(())
}
