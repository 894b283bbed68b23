//! Where the scene is seen from: cameras and camera paths ([`camera`]), and default views and the
//! headlamp for packages without cameras or lights ([`framing`]).

pub mod camera;
pub mod framing;
