//! Where the scene is seen from: cameras and camera paths ([`camera`]), and default views and the
//! headlamp for packages without cameras or lights ([`framing`]), and the frame-time target the
//! viewers hold while moving ([`frame_target`]), and what the viewers do with a scene's points of
//! interest, tours, measurements and view links ([`story`]) (the state a viewer keeps
//! for them is `crate::guide`'s).

pub mod camera;
pub mod framing;
pub mod lux;
pub mod frame_target;
pub mod story;
