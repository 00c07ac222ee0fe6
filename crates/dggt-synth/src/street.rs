//! The street's cross-section and where its junction is: shared by scene generation (where to place things) and
//! shading (where the road, its markings and the pavement are).
//!
//! Road coordinates: `yr = y - centre_y` is the lateral offset from the road's centre line. The ego lane is
//! `yr in [-3.5, 0]` (its centre is the world's `y = 0`), the oncoming lane `[0, 3.5]`, parking strips out to
//! `|yr| = 5.5`, raised sidewalks to `|yr| = 8.5` where the building facades start. A side street leaves to the
//! left (+y) at `x = side_street_x`.

/// Width of one driving lane (m).
pub const LANE_WIDTH: f64 = 3.5;
/// Lateral offset of the kerb (edge of the parking strips) from the centre line (m).
pub const KERB_OFFSET: f64 = 5.5;
/// Lateral offset of the building line from the centre line (m).
pub const FACADE_OFFSET: f64 = 8.5;
/// Height of the raised sidewalks (m).
pub const SIDEWALK_HEIGHT: f64 = 0.15;
/// Half the width of the side street (m).
pub const SIDE_STREET_HALF_WIDTH: f64 = 4.0;
/// Half the width of a painted line (m).
pub const LINE_HALF_WIDTH: f64 = 0.075;

/// Where the street lies in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Street {
    /// World y of the centre line: the ego lane's centre is at `y = 0`.
    pub centre_y: f64,
    /// World x of the side street's centre line.
    pub side_street_x: f64,
    /// Extent of the scenery along x.
    pub x_min: f64,
    pub x_max: f64,
}

impl Street {
    pub fn new(side_street_x: f64, x_min: f64, x_max: f64) -> Self {
        Self { centre_y: LANE_WIDTH / 2.0, side_street_x, x_min, x_max }
    }

    /// World y of lateral offset `yr`.
    pub fn y(&self, yr: f64) -> f64 {
        self.centre_y + yr
    }

    /// Whether `x` lies within `margin` of the side street's mouth.
    pub fn near_side_street(&self, x: f64, margin: f64) -> bool {
        (x - self.side_street_x).abs() < SIDE_STREET_HALF_WIDTH + margin
    }
}
