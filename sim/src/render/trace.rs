//! A small ray tracer over the primitive shapes of a MuJoCo scene: exact ray intersections with
//! planes, spheres, capsules, ellipsoids, cylinders and boxes in each shape's own frame, Lambert
//! shading from a headlight and a sun, the sun's shadows, and a checkered, fogged floor. Pure
//! math, no MuJoCo: [`super::Renderer`] fills the [`Shape`]s from `mjvScene`.

/// A 3-vector in `f32` (the scene's precision).
pub type V3 = [f32; 3];

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn mul(a: V3, b: V3) -> V3 {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}
/// Dot product.
pub fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
/// Cross product.
pub fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
/// `a` scaled to length 1 (`a` itself if it is zero).
pub fn normalize(a: V3) -> V3 {
    let n = dot(a, a).sqrt();
    if n > 0.0 { scale(a, 1.0 / n) } else { a }
}

/// The primitive kinds, as MuJoCo numbers them (`mjtGeom`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// `mjGEOM_PLANE`: z = 0 of its frame, half-sizes x, y (0: unbounded).
    Plane,
    /// `mjGEOM_SPHERE`: radius.
    Sphere,
    /// `mjGEOM_CAPSULE`: radius, half-length along z.
    Capsule,
    /// `mjGEOM_ELLIPSOID`: three radii.
    Ellipsoid,
    /// `mjGEOM_CYLINDER`: radius, half-length along z.
    Cylinder,
    /// `mjGEOM_BOX`: three half-sizes.
    Box,
}

impl Kind {
    /// The kind of MuJoCo geom type `t`, if this tracer draws it (meshes, height fields and the
    /// decorative lines and arrows it does not).
    pub fn from_mujoco(t: i32) -> Option<Kind> {
        Some(match t {
            0 => Kind::Plane,
            2 => Kind::Sphere,
            3 => Kind::Capsule,
            4 => Kind::Ellipsoid,
            5 => Kind::Cylinder,
            6 => Kind::Box,
            _ => return None,
        })
    }
}

/// One shape placed in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// What it is.
    pub kind: Kind,
    /// MuJoCo's size triple for the kind.
    pub size: V3,
    /// Its frame's origin.
    pub pos: V3,
    /// Its frame's orientation, row-major, local to world (`world = mat · local + pos`).
    pub mat: [f32; 9],
    /// Its colour, RGB in 0..1.
    pub rgb: V3,
}

impl Shape {
    fn to_local(&self, v: V3) -> V3 {
        let m = &self.mat;
        // matᵀ · v
        [
            m[0] * v[0] + m[3] * v[1] + m[6] * v[2],
            m[1] * v[0] + m[4] * v[1] + m[7] * v[2],
            m[2] * v[0] + m[5] * v[1] + m[8] * v[2],
        ]
    }

    fn to_world(&self, v: V3) -> V3 {
        let m = &self.mat;
        [
            m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
            m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
            m[6] * v[0] + m[7] * v[1] + m[8] * v[2],
        ]
    }

    /// The nearest hit of the ray `origin + t·dir` (t > `T_MIN`): its t and the world normal.
    pub fn hit(&self, origin: V3, dir: V3) -> Option<(f32, V3)> {
        let o = self.to_local(sub(origin, self.pos));
        let d = self.to_local(dir);
        let (t, normal) = match self.kind {
            Kind::Plane => plane(o, d, self.size),
            Kind::Sphere => sphere(o, d, self.size[0]),
            Kind::Capsule => capsule(o, d, self.size[0], self.size[1]),
            Kind::Ellipsoid => {
                let r = self.size;
                let (t, n) = sphere(
                    [o[0] / r[0], o[1] / r[1], o[2] / r[2]],
                    [d[0] / r[0], d[1] / r[1], d[2] / r[2]],
                    1.0,
                )?;
                Some((t, [n[0] / r[0], n[1] / r[1], n[2] / r[2]]))
            }
            Kind::Cylinder => cylinder(o, d, self.size[0], self.size[1]),
            Kind::Box => cuboid(o, d, self.size),
        }?;
        Some((t, normalize(self.to_world(normal))))
    }
}

/// Hits closer than this are the surface a secondary ray starts on.
const T_MIN: f32 = 1e-4;

fn plane(o: V3, d: V3, size: V3) -> Option<(f32, V3)> {
    // Seen from above only, as MuJoCo draws it.
    if o[2] <= 0.0 || d[2] >= 0.0 {
        return None;
    }
    let t = -o[2] / d[2];
    let p = add(o, scale(d, t));
    let inside = |half: f32, x: f32| half <= 0.0 || x.abs() <= half;
    (t > T_MIN && inside(size[0], p[0]) && inside(size[1], p[1])).then_some((t, [0.0, 0.0, 1.0]))
}

/// The nearer root > T_MIN of a·t² + 2b·t + c = 0.
fn nearest_root(a: f32, b: f32, c: f32) -> Option<f32> {
    let disc = b * b - a * c;
    if a.abs() < 1e-12 || disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    [(-b - s) / a, (-b + s) / a].into_iter().find(|t| *t > T_MIN)
}

fn sphere(o: V3, d: V3, r: f32) -> Option<(f32, V3)> {
    let t = nearest_root(dot(d, d), dot(o, d), dot(o, o) - r * r)?;
    Some((t, add(o, scale(d, t))))
}

fn capsule(o: V3, d: V3, r: f32, half: f32) -> Option<(f32, V3)> {
    let mut best: Option<(f32, V3)> = None;
    let mut keep = |hit: Option<(f32, V3)>| {
        if let Some((t, n)) = hit
            && best.is_none_or(|(b, _)| t < b)
        {
            best = Some((t, n));
        }
    };
    keep(side(o, d, r, half));
    for z in [-half, half] {
        keep(sphere(sub(o, [0.0, 0.0, z]), d, r));
    }
    best
}

/// The side of a z-axis cylinder of radius r between -half and half.
fn side(o: V3, d: V3, r: f32, half: f32) -> Option<(f32, V3)> {
    let a = d[0] * d[0] + d[1] * d[1];
    let b = o[0] * d[0] + o[1] * d[1];
    let c = o[0] * o[0] + o[1] * o[1] - r * r;
    let disc = b * b - a * c;
    if a < 1e-12 || disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    [(-b - s) / a, (-b + s) / a].into_iter().find_map(|t| {
        let p = add(o, scale(d, t));
        (t > T_MIN && p[2].abs() <= half).then_some((t, [p[0], p[1], 0.0]))
    })
}

fn cylinder(o: V3, d: V3, r: f32, half: f32) -> Option<(f32, V3)> {
    let mut best = side(o, d, r, half);
    if d[2].abs() > 1e-12 {
        for z in [-half, half] {
            let t = (z - o[2]) / d[2];
            let p = add(o, scale(d, t));
            if t > T_MIN && p[0] * p[0] + p[1] * p[1] <= r * r && best.is_none_or(|(b, _)| t < b) {
                best = Some((t, [0.0, 0.0, z.signum()]));
            }
        }
    }
    best
}

fn cuboid(o: V3, d: V3, half: V3) -> Option<(f32, V3)> {
    let (mut near, mut far, mut axis) = (f32::NEG_INFINITY, f32::INFINITY, 0);
    for i in 0..3 {
        if d[i].abs() < 1e-12 {
            if o[i].abs() > half[i] {
                return None;
            }
            continue;
        }
        let (a, b) = ((-half[i] - o[i]) / d[i], (half[i] - o[i]) / d[i]);
        let (a, b) = if a < b { (a, b) } else { (b, a) };
        if a > near {
            near = a;
            axis = i;
        }
        far = far.min(b);
    }
    if near > far || far <= T_MIN {
        return None;
    }
    // From inside, the exit face.
    let (t, sign) = if near > T_MIN { (near, -d[axis].signum()) } else { return None };
    let mut n = [0.0; 3];
    n[axis] = sign;
    Some((t, n))
}

/// How the picture is lit and what lies behind the shapes.
#[derive(Debug, Clone, PartialEq)]
pub struct Lighting {
    /// Direction towards the sun (normalised).
    pub sun: V3,
    /// Light that reaches every surface.
    pub ambient: f32,
    /// Strength of the light from the camera.
    pub headlight: f32,
    /// Strength of the sun.
    pub sun_strength: f32,
    /// Sky colour at the horizon and straight up.
    pub sky: (V3, V3),
    /// Side of the floor's checker squares, metres.
    pub checker: f32,
    /// Distance at which the floor has half faded into the horizon's colour.
    pub fog: f32,
}

impl Default for Lighting {
    fn default() -> Self {
        Lighting {
            sun: normalize([0.3, -0.4, 1.0]),
            ambient: 0.35,
            headlight: 0.35,
            sun_strength: 0.5,
            sky: ([0.80, 0.86, 0.92], [0.45, 0.60, 0.80]),
            checker: 1.0,
            fog: 25.0,
        }
    }
}

/// The colour seen along one camera ray.
pub fn shade(shapes: &[Shape], lighting: &Lighting, origin: V3, dir: V3) -> V3 {
    let nearest = shapes
        .iter()
        .filter_map(|s| s.hit(origin, dir).map(|(t, n)| (t, n, s)))
        .min_by(|a, b| a.0.total_cmp(&b.0));
    let Some((t, normal, shape)) = nearest else {
        let up = dir[2].clamp(0.0, 1.0);
        return add(scale(lighting.sky.0, 1.0 - up), scale(lighting.sky.1, up));
    };
    let point = add(origin, scale(dir, t));
    let lit = |to_light: V3| dot(normal, to_light).max(0.0);
    let in_sun = shapes.iter().all(|s| s.hit(point, lighting.sun).is_none());
    let light = lighting.ambient
        + lighting.headlight * lit(scale(dir, -1.0))
        + if in_sun { lighting.sun_strength * lit(lighting.sun) } else { 0.0 };
    let mut colour = scale(shape.rgb, light);
    if shape.kind == Kind::Plane {
        let local = shape.to_local(sub(point, shape.pos));
        let cell = (local[0] / lighting.checker).floor() + (local[1] / lighting.checker).floor();
        if cell.rem_euclid(2.0) >= 1.0 {
            colour = mul(colour, [0.82, 0.82, 0.82]);
        }
        let fade = t / (t + lighting.fog);
        colour = add(scale(colour, 1.0 - fade), scale(lighting.sky.0, fade));
    }
    colour.map(|c| c.clamp(0.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    const EYE: [f32; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

    fn shape(kind: Kind, size: V3, pos: V3) -> Shape {
        Shape { kind, size, pos, mat: EYE, rgb: [1.0, 0.5, 0.25] }
    }

    fn close(a: V3, b: V3) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
    }

    #[test]
    fn a_ray_down_the_x_axis_meets_each_shape_at_its_surface() {
        let (o, d) = ([-5.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
        let cases = [
            (shape(Kind::Sphere, [0.5, 0.0, 0.0], [0.0; 3]), 4.5),
            (shape(Kind::Box, [0.5, 1.0, 1.0], [0.0; 3]), 4.5),
            (shape(Kind::Ellipsoid, [2.0, 1.0, 1.0], [0.0; 3]), 3.0),
            (shape(Kind::Cylinder, [0.25, 1.0, 0.0], [0.0; 3]), 4.75),
            (shape(Kind::Capsule, [0.25, 1.0, 0.0], [0.0; 3]), 4.75),
        ];
        for (s, want) in cases {
            let (t, n) = s.hit(o, d).unwrap_or_else(|| panic!("{:?} missed", s.kind));
            assert!((t - want).abs() < 1e-5, "{:?}: t {t}, want {want}", s.kind);
            assert!(close(n, [-1.0, 0.0, 0.0]), "{:?}: normal {n:?}", s.kind);
        }
    }

    #[test]
    fn capsule_caps_and_misses() {
        // Along the axis from above: the top cap at z = half + r.
        let c = shape(Kind::Capsule, [0.25, 1.0, 0.0], [0.0; 3]);
        let (t, n) = c.hit([0.0, 0.0, 5.0], [0.0, 0.0, -1.0]).unwrap();
        assert!((t - 3.75).abs() < 1e-5 && close(n, [0.0, 0.0, 1.0]));
        // Past the side and the caps.
        assert!(c.hit([-5.0, 0.0, 1.3], [1.0, 0.0, 0.0]).is_none());
        assert!(c.hit([-5.0, 0.3, 0.0], [1.0, 0.0, 0.0]).is_none());
        // Pointing away.
        assert!(c.hit([-5.0, 0.0, 0.0], [-1.0, 0.0, 0.0]).is_none());
    }

    #[test]
    fn rotated_and_moved_shapes_are_hit_where_they_are() {
        // A capsule lying along world x (local z rotated onto x), centred at (0, 3, 0).
        let mat = [0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0];
        let c = Shape { mat, ..shape(Kind::Capsule, [0.1, 2.0, 0.0], [0.0, 3.0, 0.0]) };
        let (t, n) = c.hit([1.5, 0.0, 0.0], [0.0, 1.0, 0.0]).unwrap();
        assert!((t - 2.9).abs() < 1e-5 && close(n, [0.0, -1.0, 0.0]), "{t} {n:?}");
        assert!(c.hit([2.5, 0.0, 0.0], [0.0, 1.0, 0.0]).is_none(), "beyond its half-length and cap");
    }

    #[test]
    fn the_floor_is_seen_from_above_only_and_within_its_size() {
        let floor = shape(Kind::Plane, [10.0, 10.0, 0.0], [0.0; 3]);
        let (t, n) = floor.hit([0.0, 0.0, 2.0], normalize([1.0, 0.0, -1.0])).unwrap();
        assert!((t - 2.0 * 2f32.sqrt()).abs() < 1e-5 && close(n, [0.0, 0.0, 1.0]));
        assert!(floor.hit([0.0, 0.0, -2.0], [0.0, 0.0, 1.0]).is_none());
        assert!(floor.hit([0.0, 0.0, 1.0], normalize([20.0, 0.0, -1.0])).is_none(), "past its edge");
    }

    #[test]
    fn shadows_darken_the_floor_under_a_sphere() {
        let lighting = Lighting { sun: [0.0, 0.0, 1.0], headlight: 0.0, fog: 1e9, ..Lighting::default() };
        let floor = shape(Kind::Plane, [0.0, 0.0, 0.0], [0.0; 3]);
        let ball = shape(Kind::Sphere, [0.5, 0.0, 0.0], [0.0, 0.0, 1.0]);
        let scene = [floor, ball];
        // The floor at (0.25, 0.25) (under the ball) and at (0.25, 2.25) (in the sun), both on a light
        // checker square, seen at a low angle from +x so the ball is not in the way.
        let seen = |x: f32, y: f32| shade(&scene, &lighting, [x + 3.0, y, 1.0], normalize([-3.0, 0.0, -1.0]));
        let (shadow, sun) = (seen(0.25, 0.25), seen(0.25, 2.25));
        assert!(shadow[0] < sun[0], "{shadow:?} vs {sun:?}");
        // Missing everything shows the sky.
        assert_eq!(shade(&scene, &lighting, [0.0, 0.0, 5.0], [0.0, 0.0, 1.0]), lighting.sky.1);
    }
}
