// Shared build script (included by every crate whose binaries or tests link MuJoCo): embeds an rpath
// to the MuJoCo library folder, so binaries and tests run without LD_LIBRARY_PATH. The folder comes
// from MUJOCO_DYNAMIC_LINK_DIR, which .cargo/config.toml sets to third_party/mujoco (absolute).
fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
