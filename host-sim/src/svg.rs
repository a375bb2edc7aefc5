//! The display list as SVG: one `polyline` (or `polygon`, or `circle` for a
//! dot) per display-list polyline, in drawing order, in DAC units with y up
//! (flipped for SVG), green on black like the scope.

use crate::scene::HostDisplayList;
use std::io::Write;

/// Write `list` (DAC codes `0 ..= 2^bits - 1`) as an SVG document.
pub fn write_svg(mut w: impl Write, list: &HostDisplayList, bits: u8) -> std::io::Result<()> {
    let max = f32::from(u16::MAX >> (16 - bits.clamp(1, 16)));
    // Stroke width: about one pixel of a 1024-pixel rendering.
    let stroke = (max + 1.0) / 1024.0;
    writeln!(w, r#"<?xml version="1.0" encoding="UTF-8"?>"#)?;
    writeln!(
        w,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {max} {max}" width="1024" height="1024">"#
    )?;
    writeln!(w, r#"<rect width="100%" height="100%" fill="black"/>"#)?;
    writeln!(
        w,
        r##"<g fill="none" stroke="#3c3" stroke-width="{stroke}" stroke-linejoin="round" stroke-linecap="round">"##
    )?;
    for p in list.polylines() {
        let pts: Vec<String> = p.points.iter().map(|q| format!("{:.2},{:.2}", q.x, max - q.y)).collect();
        if p.dot || p.points.len() == 1 {
            if let Some(q) = p.points.first() {
                writeln!(w, r##"<circle cx="{:.2}" cy="{:.2}" r="{stroke}" fill="#3c3"/>"##, q.x, max - q.y)?;
            }
        } else if p.closed {
            writeln!(w, r#"<polygon points="{}"/>"#, pts.join(" "))?;
        } else {
            writeln!(w, r#"<polyline points="{}"/>"#, pts.join(" "))?;
        }
    }
    writeln!(w, "</g>\n</svg>")?;
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use isoscope_core::command::Command;
    use isoscope_core::display::DisplayStore;
    use isoscope_core::screen::ScreenPoint;

    #[test]
    fn polylines_polygons_and_dots() {
        let mut list: HostDisplayList =
            DisplayStore::with_storage(vec![ScreenPoint::default(); 8], vec![0; 8]);
        let p = ScreenPoint::new;
        for c in
            [Command::MoveTo(p(0.0, 0.0)), Command::LineTo(p(4095.0, 4095.0)), Command::Point(p(10.0, 20.0))]
        {
            list.push(c).unwrap();
        }
        let mut out = Vec::new();
        write_svg(&mut out, &list, 12).unwrap();
        let s = String::from_utf8(out).unwrap();
        assert!(s.contains(r#"viewBox="0 0 4095 4095""#));
        // y is flipped: (0, 0) is the bottom-left corner.
        assert!(s.contains(r#"<polyline points="0.00,4095.00 4095.00,0.00"/>"#), "{s}");
        assert!(s.contains(r#"cx="10.00" cy="4075.00""#), "{s}");
        assert!(s.trim_end().ends_with("</svg>"));
    }
}
