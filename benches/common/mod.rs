//! Helpers shared by the criterion benches (each bench uses a subset).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use image::imageops::FilterType;

/// The repository root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// An RGB image from the repository, resized to `size × size`, as f32 in [0, 1].
pub fn load(rel: &str, size: u32) -> Vec<f32> {
    let img = image::open(root().join(rel))
        .expect("bench image")
        .to_rgb8();
    let img = image::imageops::resize(&img, size, size, FilterType::CatmullRom);
    img.into_raw()
        .into_iter()
        .map(|v| f32::from(v) / 255.0)
        .collect()
}

/// A rayon pool of `n` threads.
pub fn pool(n: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .unwrap()
}
