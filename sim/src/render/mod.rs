//! Pictures of a task, headless, without a GPU or a display: MuJoCo builds its abstract scene
//! (`mjv_updateScene` with a tracking camera — the geoms, colours and camera frame its OpenGL
//! renderer would draw), and [`trace`] ray-traces the scene's primitive shapes on the CPU.
//!
//! The renderer keeps its own `mjData` of the task's model and copies the state into it before each
//! frame, so drawing never touches the simulation being stepped.

pub mod trace;

use std::sync::Arc;

use mujoco_rs::prelude::*;

use crate::EnvError;
use crate::physics::Physics;
use trace::{Kind, Lighting, Shape, V3};

/// An RGB picture, row by row from the top, 3 bytes per pixel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width · height · 3` bytes.
    pub rgb: Vec<u8>,
}

/// Where the camera is and how the picture is sampled.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Picture width, pixels.
    pub width: u32,
    /// Picture height, pixels.
    pub height: u32,
    /// Camera distance from the tracked body, metres (Gymnasium's Ant-v5 camera: 4).
    pub distance: f64,
    /// Camera azimuth, degrees (MuJoCo's convention: 90 looks along +y).
    pub azimuth: f64,
    /// Camera elevation, degrees (negative looks down).
    pub elevation: f64,
    /// Rays per pixel side (2: 4 rays per pixel, smoothing the edges).
    pub samples: u32,
}

impl Default for View {
    fn default() -> Self {
        View { width: 320, height: 240, distance: 4.0, azimuth: 90.0, elevation: -25.0, samples: 2 }
    }
}

/// Draws frames of one model.
pub struct Renderer {
    data: MjData<Arc<MjModel>>,
    scene: MjvScene,
    camera: MjvCamera,
    option: MjvOption,
    perturb: MjvPerturb,
    view: View,
    lighting: Lighting,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer").field("view", &self.view).finish_non_exhaustive()
    }
}

/// Geoms MuJoCo may add to a scene beyond the model's (the scene's buffer size).
const MAX_GEOMS: usize = 1000;

impl Renderer {
    /// A renderer for `physics`'s model whose camera follows its first body (the Ant's torso).
    pub fn new(physics: &Physics, view: View) -> Result<Renderer, EnvError> {
        if view.width == 0 || view.height == 0 || view.samples == 0 {
            return Err(EnvError::Render(format!(
                "a {}x{} picture with {} samples",
                view.width, view.height, view.samples
            )));
        }
        let model = physics.shared_model();
        if model.ffi().nbody < 2 {
            return Err(EnvError::Render("the model has no body to follow".into()));
        }
        let scene = MjvScene::new(&model, MAX_GEOMS);
        let mut camera = MjvCamera::new_tracking(1);
        camera.distance = view.distance;
        camera.azimuth = view.azimuth;
        camera.elevation = view.elevation;
        Ok(Renderer {
            data: MjData::new(model),
            scene,
            camera,
            option: MjvOption::default(),
            perturb: MjvPerturb::default(),
            view,
            lighting: Lighting::default(),
        })
    }

    /// The picture of `physics`'s current state.
    pub fn frame(&mut self, physics: &Physics) -> Image {
        let state = physics.data();
        self.data.qpos_mut().copy_from_slice(state.qpos());
        self.data.qvel_mut().copy_from_slice(state.qvel());
        self.data.forward();
        self.scene.update(&mut self.data, &self.option, &self.perturb, &mut self.camera);
        let shapes: Vec<Shape> = self
            .scene
            .geoms()
            .iter()
            .filter(|g| g.rgba[3] > 0.0)
            .filter_map(|g| {
                Some(Shape {
                    kind: Kind::from_mujoco(g.type_)?,
                    size: g.size,
                    pos: g.pos,
                    mat: g.mat,
                    rgb: [g.rgba[0], g.rgba[1], g.rgba[2]],
                })
            })
            .collect();
        // The two stereo halves of the GL camera; without stereo they coincide.
        let cams = &self.scene.ffi().camera;
        let pos = average(cams[0].pos, cams[1].pos);
        let forward = trace::normalize(average(cams[0].forward, cams[1].forward));
        let up = trace::normalize(average(cams[0].up, cams[1].up));
        let right = trace::normalize(trace::cross(forward, up));
        // The vertical field of view is the model's (`frustum_top` at `frustum_near`); the
        // horizontal one follows the picture's aspect ratio, as MuJoCo's viewport does.
        let half_h = cams[0].frustum_top / cams[0].frustum_near;
        let half_w = half_h * self.view.width as f32 / self.view.height as f32;
        self.trace(&shapes, pos, forward, up, right, half_w, half_h)
    }

    #[allow(clippy::too_many_arguments)]
    fn trace(
        &self,
        shapes: &[Shape],
        pos: V3,
        forward: V3,
        up: V3,
        right: V3,
        half_w: f32,
        half_h: f32,
    ) -> Image {
        let (w, h, n) = (self.view.width, self.view.height, self.view.samples);
        let mut rgb = Vec::with_capacity((w * h * 3) as usize);
        for row in 0..h {
            for col in 0..w {
                let mut sum = [0.0f32; 3];
                for sy in 0..n {
                    for sx in 0..n {
                        let x = ((col as f32 + (sx as f32 + 0.5) / n as f32) / w as f32 * 2.0 - 1.0) * half_w;
                        let y = (1.0 - (row as f32 + (sy as f32 + 0.5) / n as f32) / h as f32 * 2.0) * half_h;
                        let dir = trace::normalize([
                            forward[0] + right[0] * x + up[0] * y,
                            forward[1] + right[1] * x + up[1] * y,
                            forward[2] + right[2] * x + up[2] * y,
                        ]);
                        let c = trace::shade(shapes, &self.lighting, pos, dir);
                        sum = [sum[0] + c[0], sum[1] + c[1], sum[2] + c[2]];
                    }
                }
                let count = (n * n) as f32;
                rgb.extend(sum.map(|s| (s / count * 255.0).round() as u8));
            }
        }
        Image { width: w, height: h, rgb }
    }
}

fn average(a: V3, b: V3) -> V3 {
    [(a[0] + b[0]) * 0.5, (a[1] + b[1]) * 0.5, (a[2] + b[2]) * 0.5]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ant_model::ANT_V5_MJCF;

    /// The fraction of pixels that differ between two pictures by more than a little.
    fn changed(a: &Image, b: &Image) -> f64 {
        let differ = a
            .rgb
            .chunks(3)
            .zip(b.rgb.chunks(3))
            .filter(|(p, q)| p.iter().zip(q.iter()).any(|(x, y)| x.abs_diff(*y) > 8));
        differ.count() as f64 / (a.width * a.height) as f64
    }

    #[test]
    fn the_ant_is_drawn_and_moves() {
        let mut physics = Physics::load("ant-v5", ANT_V5_MJCF).unwrap();
        physics.forward();
        let view = View { width: 96, height: 72, samples: 1, ..View::default() };
        let mut renderer = Renderer::new(&physics, view).unwrap();
        let first = renderer.frame(&physics);
        assert_eq!(first.rgb.len(), 96 * 72 * 3);
        // Not blank: the ant's tan body, the greenish floor and the sky are all there.
        let distinct: std::collections::HashSet<&[u8]> = first.rgb.chunks(3).collect();
        assert!(distinct.len() > 50, "{} colours", distinct.len());
        let ant_like = first
            .rgb
            .chunks(3)
            .filter(|p| p[0] > p[2].saturating_add(40) && p[1] > p[2].saturating_add(10))
            .count();
        assert!(ant_like > 100, "{ant_like} tan pixels");
        // Drop it with the legs pushed: the picture changes.
        let ctrl = [1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0];
        for _ in 0..40 {
            physics.step(&ctrl, 5);
        }
        let later = renderer.frame(&physics);
        assert!(changed(&first, &later) > 0.01, "{}", changed(&first, &later));
        // Drawing reads the state; it does not change it.
        let qpos = physics.data().qpos().to_vec();
        renderer.frame(&physics);
        assert_eq!(physics.data().qpos(), &qpos[..]);
    }
}
