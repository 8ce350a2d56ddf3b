include!("../sim/rpath.rs");
