//! The cost of a model from matrices (issue 17): a clamped Euler–Bernoulli
//! beam with consistent mass (the model of `scripts/beam_mtx.py`) of about
//! 1 000 and 10 000 DOFs, written as Matrix Market files, read, checked
//! (symmetry, positive definite mass) and reduced by Craig–Bampton onto six
//! translation points with the fixed-interface modes up to 400 Hz (twice a
//! 200 Hz band) and up to 20 kHz, with the frequency check against the full
//! model up to 400 Hz.
//!
//! Before timing, each case prints its reduction (kept, modes, errors).
//!
//! Run: `cargo bench --bench reduce`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use std::fmt::Write as _;
use std::path::Path;
use tacit::model::matrix::MatrixModel;

/// Lower triangles of K and M of `ne` beam elements over 1 m (steel strip
/// 40 × 10 mm), DOFs (uy, rz) per node, 0-based.
/// Matrix entries `(row, col, value)`, 0-based.
type Entries = Vec<(usize, usize, f64)>;

fn beam(ne: usize) -> (Entries, Entries) {
    let (e, rho, b, h) = (210e9, 7850.0, 0.04, 0.01);
    let l = 1.0 / ne as f64;
    let ck = e * b * h * h * h / 12.0 / (l * l * l);
    let cm = rho * b * h * l / 420.0;
    let ke = [
        [12.0, 6.0 * l, -12.0, 6.0 * l],
        [6.0 * l, 4.0 * l * l, -6.0 * l, 2.0 * l * l],
        [-12.0, -6.0 * l, 12.0, -6.0 * l],
        [6.0 * l, 2.0 * l * l, -6.0 * l, 4.0 * l * l],
    ];
    let me = [
        [156.0, 22.0 * l, 54.0, -13.0 * l],
        [22.0 * l, 4.0 * l * l, 13.0 * l, -3.0 * l * l],
        [54.0, 13.0 * l, 156.0, -22.0 * l],
        [-13.0 * l, -3.0 * l * l, -22.0 * l, 4.0 * l * l],
    ];
    let (mut k, mut m) = (
        std::collections::BTreeMap::new(),
        std::collections::BTreeMap::new(),
    );
    for el in 0..ne {
        for a in 0..4 {
            for bb in 0..4 {
                let (i, j) = (2 * el + a, 2 * el + bb);
                if i >= j {
                    *k.entry((j, i)).or_insert(0.0) += ck * ke[a][bb];
                    *m.entry((j, i)).or_insert(0.0) += cm * me[a][bb];
                }
            }
        }
    }
    let flat = |t: std::collections::BTreeMap<(usize, usize), f64>| {
        t.into_iter().map(|((j, i), v)| (i, j, v)).collect()
    };
    (flat(k), flat(m))
}

fn write_mtx(path: &Path, n: usize, e: &[(usize, usize, f64)]) {
    let mut s = format!(
        "%%MatrixMarket matrix coordinate real symmetric\n{n} {n} {}\n",
        e.len()
    );
    for (i, j, v) in e {
        writeln!(s, "{} {} {v:e}", i + 1, j + 1).unwrap();
    }
    std::fs::write(path, s).unwrap();
}

/// Write the beam model of `ne` elements into `dir` with a cut-off.
fn write_model(dir: &Path, ne: usize, cutoff: f64) -> std::path::PathBuf {
    let n = 2 * (ne + 1);
    let (k, m) = beam(ne);
    write_mtx(&dir.join("k.mtx"), n, &k);
    write_mtx(&dir.join("m.mtx"), n, &m);
    let mut t = format!(
        "name = \"beam{ne}\"\n[matrices]\nmass = \"m.mtx\"\nstiffness = \"k.mtx\"\nfixed = [\"n0:uy\", \"n0:rz\"]\n[reduction]\ncutoff_hz = {cutoff}\n[points]\n"
    );
    for i in 0..=ne {
        writeln!(
            t,
            "\"n{i}:uy\" = {}\n\"n{i}:rz\" = {}",
            2 * i + 1,
            2 * i + 2
        )
        .unwrap();
    }
    let p = dir.join(format!("beam{ne}-{cutoff}.toml"));
    std::fs::write(&p, t).unwrap();
    p
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let mut g = c.benchmark_group("reduce");
    g.sample_size(10);
    for ne in [499usize, 4999] {
        for cutoff in [400.0, 20000.0] {
            let p = write_model(dir.path(), ne, cutoff);
            let points: Vec<String> = (1..=5)
                .map(|i| format!("n{}:uy", i * ne / 5))
                .chain(std::iter::once(format!("n{}:uy", ne / 10)))
                .collect();
            let run = || {
                let mm = MatrixModel::from_file(&p).unwrap();
                mm.reduce(&points, Some(200.0)).unwrap()
            };
            let t = std::time::Instant::now();
            let model = run();
            let r = model.matrices.as_ref().unwrap().report.clone().unwrap();
            eprintln!(
                "{} DOFs, cut-off {cutoff} Hz: {} kept + {} modes, error {:.4} % in band, {:.4} % to {} Hz; read + reduce {:.3} s (reduction {:.3} s)",
                r.full_dofs,
                r.kept.len(),
                r.modal_coordinates,
                100.0 * r.max_error_in_band,
                100.0 * r.max_error,
                r.check_up_to_hz,
                t.elapsed().as_secs_f64(),
                r.seconds
            );
            let id = format!("{}dofs-{cutoff}Hz", 2 * (ne + 1));
            g.bench_with_input(BenchmarkId::new("read_and_reduce", id), &ne, |b, _| {
                b.iter(run)
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
