//! The objects of the pushing tasks.

use super::*;

/// 10 training and 8 test objects (the test ones are unseen shapes, sizes and colours).
pub fn object_catalog() -> (Vec<ObjSpec>, Vec<ObjSpec>) {
    let spec = |name: &str, shape: ObjShape, mu_table: f32, mass: f32, color: [u8; 3]| ObjSpec {
        name: name.to_string(),
        shape,
        mu_table,
        mass,
        color,
    };
    let poly = |verts: Vec<Vec2>| ObjShape::Polygon {
        verts: centered(verts),
    };
    let v = Vec2::new;
    let train = vec![
        spec(
            "red_box",
            ObjShape::Box { w: 6.0, h: 4.0 },
            0.5,
            120.0,
            [205, 45, 40],
        ),
        spec(
            "blue_cube",
            ObjShape::Box { w: 5.0, h: 5.0 },
            0.4,
            150.0,
            [40, 80, 205],
        ),
        spec("green_disk", ObjShape::Disk { r: 2.5 }, 0.35, 90.0, [50, 170, 70]),
        spec(
            "yellow_triangle",
            ObjShape::Triangle { side: 6.0 },
            0.6,
            80.0,
            [235, 205, 45],
        ),
        spec(
            "orange_bar",
            ObjShape::Box { w: 8.0, h: 3.0 },
            0.45,
            110.0,
            [240, 135, 30],
        ),
        spec(
            "purple_hexagon",
            poly(regular_polygon(6, 3.0, 0.0)),
            0.5,
            130.0,
            [130, 60, 170],
        ),
        spec("cyan_puck", ObjShape::Disk { r: 1.75 }, 0.3, 50.0, [40, 200, 210]),
        spec(
            "brown_block",
            ObjShape::Box { w: 7.0, h: 5.0 },
            0.7,
            200.0,
            [130, 85, 45],
        ),
        spec(
            "pink_pentagon",
            poly(regular_polygon(5, 3.0, std::f32::consts::FRAC_PI_2)),
            0.55,
            100.0,
            [235, 120, 170],
        ),
        spec(
            "grey_triangle",
            ObjShape::Triangle { side: 4.5 },
            0.25,
            60.0,
            [135, 135, 135],
        ),
    ];
    let test = vec![
        spec(
            "teal_trapezoid",
            poly(vec![v(-3.5, -2.0), v(3.5, -2.0), v(2.0, 2.0), v(-2.0, 2.0)]),
            0.45,
            115.0,
            [0, 128, 128],
        ),
        spec(
            "magenta_octagon",
            poly(regular_polygon(8, 3.5, std::f32::consts::PI / 8.0)),
            0.5,
            160.0,
            [220, 0, 200],
        ),
        spec(
            "lime_big_disk",
            ObjShape::Disk { r: 3.5 },
            0.4,
            170.0,
            [170, 230, 40],
        ),
        spec(
            "navy_slab",
            ObjShape::Box { w: 7.5, h: 2.5 },
            0.65,
            140.0,
            [20, 30, 110],
        ),
        spec(
            "olive_kite",
            poly(vec![v(0.0, -4.0), v(2.5, 0.5), v(0.0, 2.5), v(-2.5, 0.5)]),
            0.3,
            70.0,
            [128, 128, 0],
        ),
        spec(
            "gold_small_cube",
            ObjShape::Box { w: 3.5, h: 3.5 },
            0.8,
            90.0,
            [215, 175, 0],
        ),
        spec(
            "maroon_big_triangle",
            ObjShape::Triangle { side: 7.5 },
            0.55,
            150.0,
            [120, 20, 35],
        ),
        spec(
            "white_rhombus",
            poly(vec![v(0.0, -2.0), v(3.8, 0.0), v(0.0, 2.0), v(-3.8, 0.0)]),
            0.2,
            75.0,
            [235, 235, 230],
        ),
    ];
    (train, test)
}
