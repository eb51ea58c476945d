//! Fits the three GPs of the synthetic benchmark problem (`numerics::gp::benchmark_problem`,
//! shared inputs, one GP per output) and prints one JSON object: wall-clock seconds for the
//! three fits and, per GP, the NLML, the fitted noise variance and each start's iterations and
//! evaluations. The peer benchmark (scripts/bench_gp.py) runs it.
//!
//!   cargo run --release -p numerics --example fit_three -- [--n 1000] [--dim 40] [--seed 1]
//!       [--starts 3] [--max-iterations 200] [--threads 1] [--data-out FILE]
//!
//! `--threads 1` fits the three one after the other on one thread (the peer's setting);
//! `--threads 3` fits them in three std threads, as the corrector does. `--data-out` writes the
//! problem first (inputs, outputs, each GP's start points and box bounds, the options), so
//! that a peer can fit exactly the same problem from exactly the same starts.

use std::error::Error;
use std::time::Instant;

use numerics::gp::{benchmark_problem, Bounds, FitOptions, FitReport, GaussianProcess};
use serde_json::json;

struct Args {
    n: usize,
    dim: usize,
    seed: u64,
    starts: usize,
    max_iterations: u64,
    threads: usize,
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
            "--data-out" => args.data_out = Some(value()?),
            other => return Err(format!("unknown argument {other}").into()),
        }
    }
    if args.threads != 1 && args.threads != 3 {
        return Err("--threads must be 1 or 3".into());
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

    let started = Instant::now();
    let reports: Vec<FitReport> = if args.threads == 1 {
        outputs
            .iter()
            .map(|y| GaussianProcess::fit(&inputs, y, &options).map(|(_, r)| r))
            .collect::<Result<_, _>>()?
    } else {
        std::thread::scope(|scope| {
            let handles: Vec<_> = outputs
                .iter()
                .map(|y| scope.spawn(|| GaussianProcess::fit(&inputs, y, &options)))
                .collect();
            handles
                .into_iter()
                .map(|h| match h.join() {
                    Ok(fit) => fit.map(|(_, r)| r).map_err(|e| e.to_string()),
                    Err(_) => Err("a fitting thread panicked".to_string()),
                })
                .collect::<Result<Vec<_>, _>>()
        })?
    };
    let seconds = started.elapsed().as_secs_f64();

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
            "fits": fits,
        })
    );
    Ok(())
}
