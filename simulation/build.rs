//! Bakes the MuJoCo library folder (set by .cargo/config.toml, filled by
//! scripts/setup.sh) into the rpath of this crate's test binaries, whose tests run
//! real tasks' episodes (through `scenarios`, which links MuJoCo).

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
