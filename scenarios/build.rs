//! Checks that MuJoCo 3.17.0 was unpacked by `scripts/setup.sh` and bakes its
//! folder into the rpath of this crate's test binaries; bakes in where
//! `scripts/setup.sh` unpacks robosuite's scene assets.

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") else {
        panic!(
            "\n\nMUJOCO_DYNAMIC_LINK_DIR is not set. Build from the repository root (its \
             .cargo/config.toml sets it), after running `scripts/setup.sh`.\n\n"
        );
    };
    let lib = std::path::Path::new(&dir).join("libmujoco.so");
    println!("cargo::rerun-if-changed={}", lib.display());
    if !lib.exists() {
        panic!(
            "\n\nMuJoCo 3.17.0 is missing: {} does not exist.\nRun `scripts/setup.sh` from the \
             repository root (it downloads the pinned mujoco==3.17.0 wheel and unpacks the \
             library there), then build again.\n\n",
            lib.display()
        );
    }
    println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
    // robosuite's scene assets, unpacked by scripts/setup.sh beside .mujoco.
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let assets = std::path::Path::new(&manifest).join("..").join(".robosuite").join("assets");
    println!("cargo::rustc-env=EVALHARNESS_ROBOSUITE_DEFAULT={}", assets.display());
}
