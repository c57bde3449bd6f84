//! Under feature `cuda`: compiles the GPU kernels' source (src/rf/gpu/kernels.cu) for the host
//! with g++, so that the tests can run the very code the GPU runs against the Rust tracer on a
//! machine without a GPU. `-ffp-contract=off` keeps g++ from fusing multiply-adds, as NVRTC's
//! `--fmad=false` keeps the GPU from it: the same IEEE operations on both.

fn main() {
    #[cfg(feature = "cuda")]
    {
        println!("cargo:rerun-if-changed=src/rf/gpu/kernels.cu");
        cc::Build::new()
            .cpp(true)
            .file("src/rf/gpu/kernels.cu")
            // g++ would otherwise take the .cu file for a linker input.
            .flag("-x")
            .flag("c++")
            .flag("-std=c++14")
            .flag("-ffp-contract=off")
            .flag("-fno-fast-math")
            .flag("-fno-exceptions")
            .opt_level(2)
            .warnings(false)
            .compile("kodama_gpu_host");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
