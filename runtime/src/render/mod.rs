//! The renderer: the state it owns ([`renderer`]), the tile pools it writes tiles into
//! ([`pool`]), and the blit that shows a frame on a surface ([`present`]).

mod chunks;
mod counters;
mod edit;
mod frame;
mod inspect;
mod light;
mod params;
pub mod pool;
pub mod present;
pub mod probe;
pub mod renderer;
mod scene_lights;
mod shadow_atlas;
pub(crate) mod shadow_queue;
mod still;
mod targets;
mod tiles;
mod transport;
mod update;

pub use counters::PassStats;
pub use counters::PassWork;
pub use edit::LightEdit;
pub use frame::{Frame, LdrOutput};
pub use light::{CarriedLight, LightProgress};
pub use params::{auto_exposure, cone_set};
pub use renderer::Renderer;
pub use still::StillProgress;
pub use tiles::SceneUpdate;
