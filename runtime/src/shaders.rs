//! WGSL sources. Each compute pass is `shaders/brdf.wgsl` and `shaders/common.wgsl` followed by its
//! own file, after the constants generated from Rust (`constants`); the splat render passes stand alone. `ALL` lists every composed module so one naga test validates them.

pub const BRDF: &str = include_str!("shaders/brdf.wgsl");
pub const COMMON: &str = include_str!("shaders/common.wgsl");
pub const ENV: &str = include_str!("passes/env.wgsl");
pub const INJECT: &str = include_str!("passes/inject.wgsl");
pub const MIP: &str = include_str!("passes/mip.wgsl");
pub const PROPAGATE: &str = include_str!("passes/propagate.wgsl");
pub const SPLAT: &str = include_str!("passes/splat.wgsl");
pub const SHADE: &str = include_str!("passes/shade.wgsl");

/// Constants shared with the Rust side, generated from it so the two cannot drift.
pub fn constants() -> String {
    use crate::rock;
    format!(
        "const ROCK_LEVEL: u32 = {}u;\nconst ROCK_BRICK_SHIFT: u32 = {}u;\nconst ROCK_HEADER_WORDS: u32 = {}u;\n\
         const ROCK_ENTRY_WORDS: u32 = {}u;\nconst ROCK_EMPTY_KEY: i32 = {};\n",
        rock::ROCK_LEVEL,
        rock::BRICK_SHIFT,
        rock::HEADER_WORDS,
        rock::ENTRY_WORDS,
        // WGSL has no literal for i32::MIN (its negation overflows): write it as an expression.
        format_args!("({} - 1)", rock::EMPTY_KEY + 1),
    )
}

/// The generated constants and common declarations followed by a pass's own WGSL.
pub fn compose(pass: &str) -> String {
    format!("{}\n{BRDF}\n{COMMON}\n{pass}", constants())
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
