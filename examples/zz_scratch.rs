use std::path::Path;
use tacit::correlate::{self, FitSettings, FrfSettings, ModalTest, Window};
use tacit::model::Model;
fn main() -> anyhow::Result<()> {
    let nominal = Model::from_file(Path::new("data/lanl8dof.toml"))?;
    let args: Vec<String> = std::env::args().collect();
    let seg: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(1024);
    let samples: usize = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(4096);
    let win = if args.get(3).map(|s| s == "rect").unwrap_or(false) { Window::Rectangular } else { Window::Hann };
    let fric: bool = args.get(4).map(|s| s == "f").unwrap_or(false);
    let mut t = if fric { ModalTest::like_the_paper() } else { ModalTest::linear() };
    t.samples = samples;
    let recs = t.simulate(&nominal)?;
    let sensors: Vec<usize> = (1..=8).collect();
    let fs = FrfSettings { segment: seg, window: win, ..Default::default() };
    let id = correlate::identify_records(&recs, Some(1), &sensors, &fs, &FitSettings::default())?;
    for p in &id.fit.poles { if p.freq_hz < 30.0 { print!("[{} {:.2} {:.2}{}] ", p.order, p.freq_hz, 100.0*p.damping, if p.stable {"s"} else {""}); } }
    println!();
    let tm = id.fit.test_modes("x", 8)?;
    let modes = tacit::modal::solve(&nominal.mass_matrix(), &nominal.stiffness_matrix())?;
    let corr = correlate::correlate(&tm, &modes, &Default::default())?;
    print!("{}", correlate::report::correlation_table(&corr, None));
    println!("support {:?} fit err {:?} mn {}", id.fit.support, id.fit.fit_error, id.fit.mass_normalized);
    for m in &tm.modes { println!("{:.3} {:.3} {:?}", m.frequency_hz, m.damping*100.0, m.shape.iter().map(|v| format!("{v:.3}")).collect::<Vec<_>>()); }
    let (phi, _) = correlate::mac::flexible_at(&modes, &sensors)?;
    println!("model mode1 {:?}", phi.column(0).iter().map(|v| format!("{v:.3}")).collect::<Vec<_>>());
    Ok(())
}
