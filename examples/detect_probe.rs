use lumen::calib::{
    detect::{BoardSize, DetectOptions},
    Config,
};
fn main() {
    let images: Vec<(String, lumen::image::filter::Grey)> = std::env::args()
        .skip(1)
        .map(|f| {
            let img = lumen::image::io::read(std::path::Path::new(&f)).unwrap();
            (f.rsplit('/').next().unwrap().to_string(), lumen::image::filter::Grey::from_image(&img))
        })
        .collect();
    let cfg = Config {
        board: BoardSize { cols: 9, rows: 6 },
        square: 1.0,
        flags: Default::default(),
        detect: DetectOptions::default(),
        max_iterations: 100,
    };
    let t = std::time::Instant::now();
    let c = lumen::calib::run(&images, &cfg).unwrap();
    println!(
        "{:.1} ms rms {:.4} K {:?} d {:?}",
        t.elapsed().as_secs_f64() * 1e3,
        c.rms_px,
        c.camera_matrix,
        c.distortion_coefficients
    );
    println!(
        "per view {:?}",
        c.per_view_rms_px.iter().map(|v| (v * 1000.0).round() / 1000.0).collect::<Vec<_>>()
    );
}
