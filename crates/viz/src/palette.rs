//! Colours: one per pipeline everywhere (map, plots, legend), fix types as receivers show them,
//! raw sensors muted so the fused results stand out.

use railfuse_catalog::messages::FixType;
use rerun::Color;

/// Pipeline colours by the order pipelines appear in the file: distinguishable on the
/// viewer's dark background, and free of the red, yellow and green that mean fix types.
const PIPELINES: [(u8, u8, u8); 8] = [
    (78, 121, 167),
    (242, 142, 43),
    (176, 122, 161),
    (118, 183, 178),
    (255, 157, 167),
    (156, 117, 95),
    (160, 203, 232),
    (186, 176, 172),
];

pub fn pipeline(index: usize) -> Color {
    let (r, g, b) = PIPELINES[index % PIPELINES.len()];
    // The first colours are a little dark on the viewer's background: lift them.
    lighten((r, g, b), 0.15)
}

/// A pipeline's ±3σ band: its colour, lighter and translucent.
pub fn band(index: usize) -> Color {
    let [r, g, b, _] = pipeline(index).to_array();
    let [r, g, b, _] = lighten((r, g, b), 0.45).to_array();
    Color::from_unmultiplied_rgba(r, g, b, 170)
}

/// A pipeline's RTS-smoothed series: its colour, darker.
pub fn smoothed(index: usize) -> Color {
    let [r, g, b, _] = pipeline(index).to_array();
    let f = |c: u8| (c as f32 * 0.6) as u8;
    Color::from_rgb(f(r), f(g), f(b))
}

fn lighten((r, g, b): (u8, u8, u8), amount: f32) -> Color {
    let f = |c: u8| (c as f32 + (255.0 - c as f32) * amount) as u8;
    Color::from_rgb(f(r), f(g), f(b))
}

pub fn truth() -> Color {
    Color::from_rgb(240, 240, 240)
}

pub fn track() -> Color {
    Color::from_rgb(120, 120, 120)
}

pub fn tunnel() -> Color {
    Color::from_rgb(60, 60, 60)
}

pub fn balise() -> Color {
    Color::from_rgb(250, 200, 0)
}

pub fn station() -> Color {
    Color::from_rgb(255, 255, 255)
}

pub fn km_mark() -> Color {
    Color::from_rgb(170, 170, 170)
}

/// Raw sensors in the shared plots: muted, distinct from each other.
pub fn raw_sensor(index: usize) -> Color {
    const RAW: [(u8, u8, u8); 4] = [
        (150, 150, 110),
        (120, 150, 150),
        (150, 120, 150),
        (130, 130, 130),
    ];
    let (r, g, b) = RAW[index % RAW.len()];
    Color::from_rgb(r, g, b)
}

/// Fix types, from best (green) to none (grey), the way receiver displays colour them.
pub fn fix_type(fix: FixType) -> Color {
    match fix {
        FixType::None => Color::from_rgb(128, 128, 128),
        FixType::Single => Color::from_rgb(220, 50, 50),
        FixType::Dgps => Color::from_rgb(230, 150, 30),
        FixType::RtkFloat => Color::from_rgb(230, 210, 40),
        FixType::RtkFixed => Color::from_rgb(40, 190, 90),
    }
}

/// Gate decisions' markers.
pub fn rejected() -> Color {
    Color::from_rgb(235, 60, 60)
}

pub fn after_lockout() -> Color {
    Color::from_rgb(255, 170, 0)
}

pub fn bound() -> Color {
    Color::from_rgb(150, 150, 150)
}
