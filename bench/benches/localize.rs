//! Criterion benchmarks of `refloc::localize` and of each of its stages on
//! the Intel map (see `docs/performance.md`).
//!
//! ```text
//! cargo bench -p refloc-bench                      # everything (~15 min)
//! cargo bench -p refloc-bench -- query/            # full queries only
//! cargo bench -p refloc-bench -- 'stage/362x360/'  # one scanner's stages
//! ```
//!
//! Environment: `REFLOC_BENCH_DB=FILE` uses a prebuilt database (as written
//! by `query-count --write-db FILE`) instead of compiling the map (~1 min);
//! `REFLOC_BENCH_SUMMARY=0` skips the per-query distribution printed first.
//!
//! Every benchmark iteration is ONE item (a query, or a candidate site of a
//! query), cycling through a fixed list, so criterion's "time" is a per-query
//! (per-candidate) time averaged over the items its samples covered. The
//! summary printed before the benchmarks gives each query's own time
//! (fastest of 3 runs) and their median / 90th percentile over the set.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, SamplingMode};
use mapc::compiler::rng::Rng;
use refloc::{localize, scratch_size, Localizer, Pose2, RefDb};
use refloc_bench::{
    candidates, median, quantile, query_stats, scan_set, Condition, Database, Kind, Query, Work,
    SCAN_COUNT,
};

type Db<'a> = RefDb<&'a [u8]>;

/// Runs `f` on one item per iteration, cycling through `n` items; `f`
/// returns the time to count (it may leave set-up work out).
fn cycle(b: &mut criterion::Bencher<'_>, n: usize, mut f: impl FnMut(usize) -> Duration) {
    let mut next = 0usize;
    b.iter_custom(|iters| {
        let mut total = Duration::ZERO;
        for _ in 0..iters {
            total += f(next % n.max(1));
            next += 1;
        }
        total
    });
}

fn timed<T>(f: impl FnOnce() -> T) -> Duration {
    let t = Instant::now();
    black_box(f());
    t.elapsed()
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Per-query distribution of the full query, per scan set.
fn summary(db: &Db<'_>, sets: &[(Kind, Condition, Vec<Query>)]) {
    println!(
        "\nper-query times, single thread, fastest of 3 runs per query, {SCAN_COUNT} queries per set:"
    );
    println!(
        "{:<18} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8} {:>6} {:>6} {:>6} {:>8} {:>7} {:>6} {:>6}",
        "set",
        "median",
        "p90",
        "max",
        "mean",
        "min",
        "examined",
        "max",
        "=1",
        "N_C",
        "accepted",
        "correct",
        "M/max",
        "expl."
    );
    for (kind, cond, qs) in sets {
        let st = query_stats(db, qs, 3);
        let t: Vec<Duration> = st.iter().map(|s| s.time).collect();
        let n = st.len().max(1) as f64;
        let mean = t.iter().sum::<Duration>() / st.len().max(1) as u32;
        println!(
            "{:<18} {:>7.2}ms {:>7.2}ms {:>7.2}ms {:>7.2}ms {:>7.2}ms {:>8.1} {:>6} {:>6} {:>6.1} {:>8} {:>7} {:>6.3} {:>6.3}",
            format!("{}/{}", kind.name(), cond.name()),
            ms(median(&t)),
            ms(quantile(&t, 0.9)),
            ms(quantile(&t, 1.0)),
            ms(mean),
            ms(quantile(&t, 0.0)),
            st.iter().map(|s| s.examined as f64).sum::<f64>() / n,
            st.iter().map(|s| s.examined).max().unwrap_or(0),
            st.iter().filter(|s| s.examined == 1).count(),
            st.iter().map(|s| s.nc as f64).sum::<f64>() / n,
            st.iter().filter(|s| s.accepted).count(),
            st.iter().filter(|s| s.correct).count(),
            st.iter().map(|s| s.vicinity_ratio as f64).sum::<f64>() / n,
            st.iter().map(|s| s.explained_ratio as f64).sum::<f64>() / n,
        );
    }
    println!(
        "(examined: candidates the fine stage ran, mean and max; =1: queries that stopped at the \
         first candidate; N_C: coarse candidate count, mean; \
         M/max: the answer's vicinity score M / (4.5 N_P), mean; expl.: M / (4.5 (N_P - short beams)), \
         mean; the early stop needs expl. >= early_accept = {} with at most N_P/5 short beams)\n",
        db.params().select.early_accept
    );
}

fn bench_queries(c: &mut Criterion, db: &Db<'_>, sets: &[(Kind, Condition, Vec<Query>)]) {
    let mut g = c.benchmark_group("query");
    g.sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .warm_up_time(Duration::from_secs(2))
        .measurement_time(Duration::from_secs(10));
    for (kind, cond, qs) in sets {
        let mut scratch = vec![0u8; scratch_size(db.params(), kind.beams())];
        g.bench_function(BenchmarkId::new(kind.name(), cond.name()), |b| {
            cycle(b, qs.len(), |i| {
                let scan = qs[i].scan();
                let t = Instant::now();
                let r = localize(db, black_box(&scan), &mut scratch);
                let e = t.elapsed();
                black_box(&r);
                e
            })
        });
    }
    g.finish();
}

/// Shuffles deterministically (Fisher-Yates with a fixed seed), so any run
/// of consecutive items is a fair sample of the whole list.
fn shuffled<T>(mut v: Vec<T>, seed: u64) -> Vec<T> {
    let mut r = Rng::new(seed);
    for i in (1..v.len()).rev() {
        let j = r.below(i as u64 + 1) as usize;
        v.swap(i, j);
    }
    v
}

/// Runs `f` on the localizer with query `q` prepared, and returns what `f`
/// timed (zero when the localizer rejects the scan).
fn on_query<D: AsRef<[u8]>>(
    work: &mut Work,
    db: &RefDb<D>,
    q: &Query,
    f: impl FnOnce(&mut Localizer<'_, '_, D>) -> Duration,
) -> Duration {
    work.prepared(db, q)
        .map_or(Duration::ZERO, |mut loc| f(&mut loc))
}

fn bench_stages(c: &mut Criterion, db: &Db<'_>, kind: Kind, cond: Condition, qs: &[Query]) {
    let mut work = Work::new(db, kind.beams());
    // (query, site) pairs of every query's coarse candidate list.
    let pairs: Vec<(usize, usize)> = qs
        .iter()
        .enumerate()
        .flat_map(|(i, q)| {
            candidates(db, q, &mut work)
                .into_iter()
                .map(move |s| (i, s))
        })
        .collect();
    let pairs = shuffled(pairs, 7);
    // Queries whose correct site SSM matches: (query, site, SSM sensor pose, refined pose).
    let correct: Vec<(usize, usize, Pose2, Pose2)> = qs
        .iter()
        .enumerate()
        .filter_map(|(i, q)| {
            let site = q.correct_site?;
            let mut loc = work.prepared(db, q)?;
            let m = loc.match_site(site)?;
            let s = loc.sensor_pose(site, &m);
            Some((i, site, s, loc.refine_pose(s)))
        })
        .collect();
    println!(
        "stage inputs {}/{}: {} queries, {} with a correct site whose SSM matched, {} coarse candidate pairs",
        kind.name(),
        cond.name(),
        qs.len(),
        correct.len(),
        pairs.len()
    );

    let mut g = c.benchmark_group(format!("stage/{}/{}", kind.name(), cond.name()));
    g.sampling_mode(SamplingMode::Flat)
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4));
    g.bench_function("histogram", |b| {
        cycle(b, qs.len(), |i| {
            on_query(&mut work, db, &qs[i], |loc| timed(|| loc.histogram()))
        })
    });
    g.bench_function("coarse", |b| {
        cycle(b, qs.len(), |i| {
            on_query(&mut work, db, &qs[i], |loc| {
                loc.histogram();
                timed(|| loc.rank_sites())
            })
        })
    });
    g.bench_function("query_prep", |b| {
        cycle(b, qs.len(), |i| {
            work.localizer(db).map_or(Duration::ZERO, |mut loc| {
                timed(|| loc.prepare(&qs[i].scan()).is_ok())
            })
        })
    });
    if !correct.is_empty() {
        g.bench_function("ssm_correct", |b| {
            cycle(b, correct.len(), |i| {
                let (q, site, ..) = correct[i];
                on_query(&mut work, db, &qs[q], |loc| timed(|| loc.match_site(site)))
            })
        });
    }
    if !pairs.is_empty() {
        g.bench_function("ssm_candidate", |b| {
            cycle(b, pairs.len(), |i| {
                let (q, site) = pairs[i];
                on_query(&mut work, db, &qs[q], |loc| timed(|| loc.match_site(site)))
            })
        });
        // The whole per-candidate body of the localizer's fine loop.
        g.bench_function("candidate", |b| {
            cycle(b, pairs.len(), |i| {
                let (q, site) = pairs[i];
                on_query(&mut work, db, &qs[q], |loc| {
                    timed(|| {
                        loc.match_site(site).map(|m| {
                            let s = loc.refine_pose(loc.sensor_pose(site, &m));
                            loc.verify_pose(&s)
                        })
                    })
                })
            })
        });
    }
    if !correct.is_empty() {
        g.bench_function("refine", |b| {
            cycle(b, correct.len(), |i| {
                let (q, _, s, _) = correct[i];
                on_query(&mut work, db, &qs[q], |loc| timed(|| loc.refine_pose(s)))
            })
        });
        g.bench_function("verify", |b| {
            cycle(b, correct.len(), |i| {
                let (q, _, _, s) = correct[i];
                on_query(&mut work, db, &qs[q], |loc| timed(|| loc.verify_pose(&s)))
            })
        });
    }
    g.finish();
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    let t = Instant::now();
    let fixture = match std::env::var_os("REFLOC_BENCH_DB") {
        Some(p) => Database::load(p.as_ref()),
        None => Database::build(),
    };
    let fixture = match fixture {
        Ok(f) => f,
        Err(e) => {
            eprintln!("refloc-bench: cannot make the database: {e}");
            std::process::exit(2);
        }
    };
    let db = fixture.open();
    println!("database: {}", fixture.origin);
    println!(
        "sites {}, scratch {} B for 362 beams, {} B for 1081 beams",
        db.site_count(),
        scratch_size(db.params(), 362),
        scratch_size(db.params(), 1081)
    );
    let mut sets = Vec::new();
    for kind in Kind::ALL {
        for cond in Condition::ALL {
            sets.push((kind, cond, scan_set(&db, kind, cond, SCAN_COUNT)));
        }
    }
    println!(
        "{SCAN_COUNT} scans per set simulated; set-up {:.1} s",
        t.elapsed().as_secs_f64()
    );
    if std::env::var("REFLOC_BENCH_SUMMARY").map_or(true, |v| v != "0") {
        summary(&db, &sets);
    }
    bench_queries(&mut c, &db, &sets);
    for (kind, cond, qs) in &sets {
        bench_stages(&mut c, &db, *kind, *cond, qs);
    }
    c.final_summary();
}
