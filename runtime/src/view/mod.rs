//! Where the scene is seen from: cameras and camera paths ([`camera`]), and default views and the
//! headlamp for packages without cameras or lights ([`framing`]), and the frame-time target the
//! viewers hold while moving ([`frame_target`]).

pub mod camera;
pub mod framing;
pub mod frame_target;
