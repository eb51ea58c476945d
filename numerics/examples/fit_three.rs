//! Fits the three GPs of the synthetic benchmark problem (`numerics::gp::benchmark_problem`,
//! shared inputs, one GP per output) and prints one JSON object: wall-clock seconds for the
//! three fits and, per GP, the NLML, the fitted noise variance and each start's iterations and
//! evaluations; the fits' floating-point operations (`numerics::gp::evaluation_flops` per
//! evaluation, `model_flops` per final model), the rate they ran at, and the machine's practical
//! peak on one core measured in the same process: the median rate of a 2000 × 2000 faer matrix
//! product on one thread, before the fits and after them. Rates are given by wall-clock time
//! and by the thread's time on a CPU (Linux's `/proc/thread-self/schedstat`): on a machine
//! shared with other work the wall clock also counts the time spent waiting for a CPU, so the
//! fraction of the peak is taken from CPU times, the fits' and the products' alike. The peer
//! benchmark (scripts/bench_gp.py) runs it.
//!
//!   cargo run --release -p numerics --example fit_three -- [--n 1000] [--dim 40] [--seed 1]
//!       [--starts 3] [--max-iterations 200] [--threads 1] [--parallel T] [--data-out FILE]
//!
//! `--threads 1` fits the three one after the other on one thread (the peer's setting);
//! `--threads T` fits them with `GaussianProcess::fit_many` on T threads. `--parallel T` then
//! fits them again with `fit_many` on T threads, reports that time too and checks that both
//! runs found the same hyperparameters, bit for bit. `--data-out` writes the problem first
//! (inputs, outputs, each GP's start points and box bounds, the options), so that a peer can
//! fit exactly the same problem from exactly the same starts.

use std::error::Error;
use std::time::Instant;

use faer::{Accum, Mat, Par};
use numerics::gp::{
    benchmark_problem, evaluation_flops, model_flops, Bounds, FitOptions, FitReport,
    GaussianProcess, Inputs,
};
use serde_json::json;

struct Args {
    n: usize,
    dim: usize,
    seed: u64,
    starts: usize,
    max_iterations: u64,
    threads: usize,
    parallel: Option<usize>,
    data_out: Option<String>,
}

fn parse_args() -> Result<Args, Box<dyn Error>> {
    let mut args = Args {
        n: 1000,
        dim: 40,
        seed: 1,
        starts: 3,
        max_iterations: 200,
        threads: 1,
        parallel: None,
        data_out: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--n" => args.n = value()?.parse()?,
            "--dim" => args.dim = value()?.parse()?,
            "--seed" => args.seed = value()?.parse()?,
            "--starts" => args.starts = value()?.parse()?,
            "--max-iterations" => args.max_iterations = value()?.parse()?,
            "--threads" => args.threads = value()?.parse()?,
            "--parallel" => args.parallel = Some(value()?.parse()?),
            "--data-out" => args.data_out = Some(value()?),
            other => return Err(format!("unknown argument {other}").into()),
        }
    }
    if args.threads == 0 || args.parallel == Some(0) {
        return Err("--threads and --parallel must be at least 1".into());
    }
    Ok(args)
}

fn main() -> Result<(), Box<dyn Error>> {
    let args = parse_args()?;
    let (inputs, outputs) = benchmark_problem(args.seed, args.n, args.dim)?;
    let options = FitOptions {
        starts: args.starts,
        seed: args.seed,
        max_iterations: args.max_iterations,
        ..FitOptions::default()
    };

    if let Some(path) = &args.data_out {
        let mut problems = Vec::new();
        for y in &outputs {
            let starts: Vec<Vec<f64>> = options
                .start_points(&inputs, y)?
                .iter()
                .map(|h| h.to_log_vector())
                .collect();
            let bounds = Bounds::from_data(&inputs, y, options.noise_floor)?;
            problems.push(json!({
                "targets": y,
                "starts": starts,
                "lower": bounds.lower,
                "upper": bounds.upper,
            }));
        }
        let data = json!({
            "n": args.n,
            "dim": args.dim,
            "seed": args.seed,
            "inputs": inputs.as_row_major(),
            "outputs": problems,
            "max_iterations": options.max_iterations,
            "gradient_tolerance": options.gradient_tolerance,
            "cost_tolerance": options.cost_tolerance,
            "history": options.history,
        });
        std::fs::write(path, serde_json::to_vec(&data)?)?;
    }

    let peak_before = peak_gflops();
    let (seconds, cpu_seconds, reports) = fit_all(&inputs, &outputs, &options, args.threads)?;
    let parallel = match args.parallel {
        Some(threads) => {
            let (seconds, _, parallel_reports) = fit_all(&inputs, &outputs, &options, threads)?;
            let same = reports
                .iter()
                .zip(&parallel_reports)
                .all(|(a, b)| a.nlml.to_bits() == b.nlml.to_bits() && a.starts == b.starts);
            Some(json!({ "threads": threads, "seconds": seconds, "same_results": same }))
        }
        None => None,
    };
    let peak_after = peak_gflops();
    let peak = Rates {
        wall: 0.5 * (peak_before.wall + peak_after.wall),
        cpu: 0.5 * (peak_before.cpu + peak_after.cpu),
    };

    let evaluations: usize = reports
        .iter()
        .flat_map(|r| r.starts.iter().map(|s| s.evaluations))
        .sum();
    let flops = evaluations as f64 * evaluation_flops(args.n, args.dim)
        + reports.len() as f64 * model_flops(args.n, args.dim);
    let gflops = Rates {
        wall: flops / seconds / 1e9,
        cpu: flops / cpu_seconds / 1e9,
    };

    let fits: Vec<_> = reports
        .iter()
        .map(|r| {
            let best = &r.starts[r.best_start];
            json!({
                "nlml": r.nlml,
                "theta": best.end.to_log_vector(),
                "noise_variance": best.end.noise_variance(),
                "jitter": r.jitter,
                "iterations": r.starts.iter().map(|s| s.iterations).collect::<Vec<_>>(),
                "evaluations": r.starts.iter().map(|s| s.evaluations).collect::<Vec<_>>(),
                "start_nlml": r.starts.iter().map(|s| s.nlml).collect::<Vec<_>>(),
                "termination": r.starts.iter().map(|s| s.termination.clone()).collect::<Vec<_>>(),
            })
        })
        .collect();
    println!(
        "{}",
        json!({
            "n": args.n,
            "dim": args.dim,
            "starts": args.starts,
            "threads": args.threads,
            "seconds": seconds,
            "evaluations": evaluations,
            "flops_per_evaluation": evaluation_flops(args.n, args.dim),
            "flops": flops,
            "cpu_seconds": cpu_seconds,
            "gflops": gflops.wall,
            "gflops_cpu": gflops.cpu,
            "peak_gflops": peak.wall,
            "peak_gflops_cpu": peak.cpu,
            "peak_gflops_cpu_before_after": [peak_before.cpu, peak_after.cpu],
            "fraction_of_peak": gflops.cpu / peak.cpu,
            "fraction_of_peak_wall": gflops.wall / peak.wall,
            "parallel": parallel,
            "fits": fits,
        })
    );
    Ok(())
}

/// The three fits on `threads` threads (1: `GaussianProcess::fit` one after the other), timed:
/// wall-clock seconds and this thread's CPU seconds (meaningful with `threads` = 1).
fn fit_all(
    inputs: &Inputs,
    outputs: &[Vec<f64>; 3],
    options: &FitOptions,
    threads: usize,
) -> Result<(f64, f64, Vec<FitReport>), Box<dyn Error>> {
    let started = Instant::now();
    let cpu_started = thread_cpu_seconds();
    let reports: Vec<FitReport> = if threads == 1 {
        outputs
            .iter()
            .map(|y| GaussianProcess::fit(inputs, y, options).map(|(_, r)| r))
            .collect::<Result<_, _>>()?
    } else {
        let targets: Vec<&[f64]> = outputs.iter().map(|y| y.as_slice()).collect();
        GaussianProcess::fit_many(inputs, &targets, options, threads)
            .into_iter()
            .map(|fit| fit.map(|(_, r)| r))
            .collect::<Result<_, _>>()?
    };
    let wall = started.elapsed().as_secs_f64();
    let cpu = match (cpu_started, thread_cpu_seconds()) {
        (Some(a), Some(b)) => b - a,
        _ => wall,
    };
    Ok((wall, cpu, reports))
}

/// This thread's time on a CPU so far (the first field of `/proc/thread-self/schedstat`, in
/// nanoseconds), where Linux gives it.
fn thread_cpu_seconds() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let nanoseconds: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(nanoseconds * 1e-9)
}

/// Rates in GFLOP/s by wall-clock time and by CPU time.
struct Rates {
    wall: f64,
    cpu: f64,
}

/// The practical peak of one core: the median rates of seven 2000 × 2000 by 2000 × 2000 faer
/// products (`2 · 2000³` operations each) on one thread.
fn peak_gflops() -> Rates {
    const M: usize = 2000;
    let flops = 2.0 * (M as f64).powi(3);
    let a = Mat::<f64>::from_fn(M, M, |i, j| ((i * 7 + j * 3) % 11) as f64 * 0.1 - 0.5);
    let b = Mat::<f64>::from_fn(M, M, |i, j| ((i * 5 + j * 13) % 17) as f64 * 0.05 - 0.4);
    let mut c = Mat::<f64>::zeros(M, M);
    let (mut wall, mut cpu): (Vec<f64>, Vec<f64>) = (0..7)
        .map(|_| {
            let started = Instant::now();
            let cpu_started = thread_cpu_seconds();
            faer::linalg::matmul::matmul(
                c.as_mut(),
                Accum::Replace,
                a.as_ref(),
                b.as_ref(),
                1.0,
                Par::Seq,
            );
            let seconds = started.elapsed().as_secs_f64();
            let cpu_seconds = match (cpu_started, thread_cpu_seconds()) {
                (Some(a), Some(b)) => b - a,
                _ => seconds,
            };
            (flops / seconds / 1e9, flops / cpu_seconds / 1e9)
        })
        .unzip();
    std::hint::black_box(&c);
    wall.sort_by(f64::total_cmp);
    cpu.sort_by(f64::total_cmp);
    Rates {
        wall: wall[wall.len() / 2],
        cpu: cpu[cpu.len() / 2],
    }
}
