//! The board's picture as SVG: one `polyline` (a closed loop ends where it
//! began) or `circle` (a dot) per polyline of the drawing commands, in
//! drawing order, in DAC units with y up (flipped for SVG), green on black
//! like the scope.

use isoscope_core::command::Command;
use isoscope_core::view::ScreenPoint;
use std::io::Write;

/// Write the drawing `commands` (DAC codes `0 ..= 2^bits - 1`) as an SVG
/// document.
pub fn write_svg(mut w: impl Write, commands: &[Command<ScreenPoint>], bits: u8) -> std::io::Result<()> {
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
    let mut line: Vec<ScreenPoint> = Vec::new();
    let flush = |w: &mut dyn Write, line: &mut Vec<ScreenPoint>| -> std::io::Result<()> {
        if line.len() > 1 {
            let pts: Vec<String> = line.iter().map(|q| format!("{:.2},{:.2}", q.x, max - q.y)).collect();
            writeln!(w, r#"<polyline points="{}"/>"#, pts.join(" "))?;
        }
        line.clear();
        Ok(())
    };
    for c in commands {
        match *c {
            Command::MoveTo(p) => {
                flush(&mut w, &mut line)?;
                line.push(p);
            }
            Command::LineTo(p) => line.push(p),
            Command::Point(q) => {
                flush(&mut w, &mut line)?;
                writeln!(w, r##"<circle cx="{:.2}" cy="{:.2}" r="{stroke}" fill="#3c3"/>"##, q.x, max - q.y)?;
            }
        }
    }
    flush(&mut w, &mut line)?;
    writeln!(w, "</g>\n</svg>")?;
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn polylines_and_dots() {
        let p = ScreenPoint::new;
        let list =
            [Command::MoveTo(p(0.0, 0.0)), Command::LineTo(p(4095.0, 4095.0)), Command::Point(p(10.0, 20.0))];
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
