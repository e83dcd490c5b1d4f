use lumen::calib::detect::{corner_candidates, detect, BoardSize, DetectOptions};
fn main() {
    for f in std::env::args().skip(1) {
        let img = lumen::image::io::read(std::path::Path::new(&f)).unwrap();
        let g = lumen::image::filter::Grey::from_image(&img);
        let cands = corner_candidates(&g, &g.blur(1.0));
        let s: Vec<String> = cands.iter().map(|p| format!("{} {}", p.x, p.y)).collect();
        std::fs::write(format!("/tmp/cands_{}.txt", f.rsplit('/').next().unwrap()), s.join("\n")).unwrap();
        let t = std::time::Instant::now();
        match detect(&g, BoardSize { cols: 9, rows: 6 }, &DetectOptions::default()) {
            Ok(c) => println!("{f}: ok {:.1} ms c0 {:.2} c8 {:.2} c45 {:.2}", t.elapsed().as_secs_f64() * 1e3, c[0], c[8], c[45]),
            Err(e) => println!("{f}: {} candidates; {e}", cands.len()),
        }
    }
}
