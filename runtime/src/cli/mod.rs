//! What the command line does besides showing a window (native only): the render and bench jobs
//! ([`render_job`]), describing and verifying packages ([`inspect`]), exporting points
//! ([`export`]), writing images ([`image_out`]), publishing a static site ([`publish`]), drawing
//! labels into images ([`labels`]) and packing a scan given where a package is expected ([`scan_input`]).

pub mod bench_job;
pub mod export;
pub mod image_out;
pub mod inspect;
pub mod labels;
pub mod map;
pub mod publish;
pub mod render_job;
pub mod scan_input;
