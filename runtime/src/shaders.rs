//! WGSL sources. Each compute pass is `shaders/brdf.wgsl` and `shaders/common.wgsl` followed by its
//! own file; the splat render passes stand alone. `ALL` lists every composed module so one naga test validates them.

pub const BRDF: &str = include_str!("shaders/brdf.wgsl");
pub const COMMON: &str = include_str!("shaders/common.wgsl");
pub const ENV: &str = include_str!("passes/env.wgsl");
pub const INJECT: &str = include_str!("passes/inject.wgsl");
pub const MIP: &str = include_str!("passes/mip.wgsl");
pub const PROPAGATE: &str = include_str!("passes/propagate.wgsl");
pub const SPLAT: &str = include_str!("passes/splat.wgsl");
pub const SHADE: &str = include_str!("passes/shade.wgsl");

/// The common declarations followed by a pass's own WGSL.
pub fn compose(pass: &str) -> String {
    format!("{BRDF}\n{COMMON}\n{pass}")
}

/// (name, complete module source) of every shader module the runtime creates.
pub fn all() -> Vec<(&'static str, String)> {
    vec![
        ("env", compose(ENV)),
        ("inject", compose(INJECT)),
        ("mip", compose(MIP)),
        ("propagate", compose(PROPAGATE)),
        ("shade", compose(SHADE)),
        ("splat", SPLAT.to_string()),
    ]
}
