//! What the command line does besides showing a window (native only): the render and bench jobs
//! ([`render_job`]), describing and verifying packages ([`inspect`]), exporting points
//! ([`export`]), writing images ([`image_out`]) and publishing a static site ([`publish`]).

pub mod export;
pub mod image_out;
pub mod inspect;
pub mod publish;
pub mod render_job;
