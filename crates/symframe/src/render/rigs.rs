//! Light rigs for synthetic captures: unit light directions (surface toward light, camera
//! frame). Lights read from a `.lp` file are the I/O crate's job (`symframe_io::open_dataset`).

use glam::DVec3;

/// Number of columns of the DiLiGenT-like grid ([`diligent_lights`]).
pub(crate) const DILIGENT_COLS: usize = 12;
/// Number of rows of the DiLiGenT-like grid ([`diligent_lights`]).
pub(crate) const DILIGENT_ROWS: usize = 8;
/// Largest angle between a light of the DiLiGenT-like grid and the view, in degrees.
pub(crate) const DILIGENT_MAX_ANGLE_DEG: f64 = 45.0;

/// A DiLiGenT-like rig: 96 lights on a regular 12 x 8 grid (12 across, 8 down) of LED
/// positions on a plane facing the object, like the LED board of the DiLiGenT benchmark (Shi
/// et al. 2016), with the grid's corners a hair inside 45 degrees of the view. See
/// `grid_lights`.
pub fn diligent_lights() -> Vec<DVec3> {
    grid_lights(DILIGENT_COLS, DILIGENT_ROWS, DILIGENT_MAX_ANGLE_DEG)
}

/// Lights at the nodes of a regular `cols x rows` grid (equal spacing across and down) on the
/// plane `z = 1` in front of the object, centred on the view axis and scaled so that the corner
/// lights are at `0.999 * max_angle_deg` from the view; every light is then within
/// `max_angle_deg` of it. Distant-light model: each light's direction is its normalised grid
/// position. Order: row by row from the top (largest y), left (smallest x) to right in each row.
///
/// # Panics
/// If `cols` or `rows` is 0, or `max_angle_deg` is not in `(0, 90)`.
pub(crate) fn grid_lights(cols: usize, rows: usize, max_angle_deg: f64) -> Vec<DVec3> {
    assert!(cols > 0 && rows > 0, "grid_lights: empty grid");
    assert!(
        max_angle_deg > 0.0 && max_angle_deg < 90.0,
        "grid_lights: max_angle_deg must be in (0, 90)"
    );
    let half_x = (cols - 1) as f64 / 2.0;
    let half_y = (rows - 1) as f64 / 2.0;
    let corner = half_x.hypot(half_y);
    let spacing = if corner > 0.0 {
        (0.999 * max_angle_deg).to_radians().tan() / corner
    } else {
        0.0
    };
    let mut lights = Vec::with_capacity(cols * rows);
    for r in 0..rows {
        for c in 0..cols {
            let x = (c as f64 - half_x) * spacing;
            let y = (half_y - r as f64) * spacing;
            lights.push(DVec3::new(x, y, 1.0).normalize());
        }
    }
    lights
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diligent_rig_has_96_lights_within_45_degrees() {
        let l = diligent_lights();
        assert_eq!(l.len(), 96);
        let angles: Vec<f64> = l
            .iter()
            .map(|d| d.z.clamp(-1.0, 1.0).acos().to_degrees())
            .collect();
        let max = angles.iter().cloned().fold(0.0, f64::max);
        assert!(max < 45.0 && max > 44.9, "max angle {max}");
        for d in &l {
            assert!((d.length() - 1.0).abs() < 1e-12);
        }
        // Symmetric about the view: the mean direction is the view axis.
        let mean = l.iter().fold(DVec3::ZERO, |a, &b| a + b) / 96.0;
        assert!(mean.x.abs() < 1e-12 && mean.y.abs() < 1e-12);
        // Row-major from the top left.
        assert!(l[0].x < 0.0 && l[0].y > 0.0 && l[95].x > 0.0 && l[95].y < 0.0);
        assert!(l[1].x > l[0].x && l[1].y / l[1].z == l[0].y / l[0].z && l[12].y < l[0].y);
        // A regular grid: equal steps along a row once projected back onto z = 1.
        let step = |a: DVec3, b: DVec3| b.x / b.z - a.x / a.z;
        assert!((step(l[0], l[1]) - step(l[5], l[6])).abs() < 1e-12);
    }

    #[test]
    fn a_single_light_grid_is_the_view() {
        assert_eq!(grid_lights(1, 1, 30.0), vec![DVec3::Z]);
    }
}
