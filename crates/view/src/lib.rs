//! # megaray-view: the interactive view core
//!
//! What both viewers are made of (the window of `megaray view` and the browser page of
//! `megaray serve`, thin front ends in the CLI): a fly camera moved by keys, drags and the
//! wheel, a frame loop that keeps to a time budget while the camera moves and accumulates
//! progressive frames at full resolution when it stops, and the statistics a viewer shows.
//! Scripts of input drive it without a person (tests, `megaray view --script`).
//!
//! | module | holds |
//! |---|---|
//! | `camera.rs` | [`Pose`], [`FlyCamera`] |
//! | `input.rs` | [`Key`] (by role), [`Event`], [`Script`] |
//! | `core.rs` | [`ViewCore`], [`ViewOptions`], [`ViewStats`] |
//! | `overlay.rs` | the statistics line and help drawn over the picture |
//! | `viewpoint.rs` | [`Viewpoint`]: a saved view (camera, shading, what is shown) as JSON |
//! | `pick.rs` | [`pick`]: exact picking and measuring through the full-detail index |
//!
//! ```no_run
//! use megaray_scene::Scene;
//! use megaray_trace::Tracer;
//! use megaray_view::{Event, Key, ViewCore, ViewOptions};
//! let scene = Scene::open("model.mray".as_ref()).unwrap();
//! let tracer = Tracer::new(&scene).with_lod_error(1.0);
//! let pool = rayon::ThreadPoolBuilder::new().build().unwrap();
//! let mut view = ViewCore::new(&tracer, &pool, ViewOptions::new(640, 480));
//! view.handle(Event::Key(Key::Forward, true));
//! view.step(1.0 / 30.0);
//! let (w, h, rgb) = view.display();
//! ```

mod camera;
mod core;
mod input;
mod overlay;
pub mod pick;
pub mod viewpoint;

pub use crate::camera::{FlyCamera, Pose};
pub use crate::core::{FrameSource, PartOp, ViewCore, ViewOptions, ViewStats};
pub use crate::input::{help_lines, Event, Key, Script, ScriptError, Step};
pub use crate::pick::{pick, Picked};
pub use crate::viewpoint::Viewpoint;
