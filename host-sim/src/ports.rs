//! The machine's serial ports: list them, say which look like a board
//! (an ST-LINK's virtual COM port, a common USB-UART adapter), and pick
//! the one board for `--port auto`.
//!
//! Listing and choosing are pure functions over [`PortInfo`] lists, so
//! that they can be tested without hardware; [`available`] asks the
//! system through the `serialport` crate.

use anyhow::{Result, bail};
use std::fmt::Write as _;

/// How a port is attached.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Attachment {
    /// A USB device: its ids and, when it says, who made it and what it is.
    Usb {
        /// Vendor id.
        vid: u16,
        /// Product id.
        pid: u16,
        /// Manufacturer string.
        manufacturer: Option<String>,
        /// Product string.
        product: Option<String>,
    },
    /// A PCI (built-in) port.
    Pci,
    /// A Bluetooth serial link.
    Bluetooth,
    /// Not known (a SoC UART, a legacy port, a virtual one).
    Unknown,
}

/// One serial port.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PortInfo {
    /// The name to open: /dev/ttyACM0, COM3.
    pub name: String,
    /// How it is attached.
    pub attachment: Attachment,
}

/// USB vendors whose serial ports are likely the board: the ST-LINK's
/// virtual COM port, then the common USB-UART adapters.
pub const LIKELY_VENDORS: [(u16, &str); 5] = [
    (0x0483, "ST-LINK virtual COM port"),
    (0x0403, "FTDI USB-UART"),
    (0x10c4, "CP210x USB-UART"),
    (0x1a86, "CH340 USB-UART"),
    (0x067b, "Prolific USB-UART"),
];

impl PortInfo {
    /// What the port likely is, if it looks like a board: a USB port of
    /// one of [`LIKELY_VENDORS`].
    pub fn likely_board(&self) -> Option<&'static str> {
        match self.attachment {
            Attachment::Usb { vid, .. } => {
                LIKELY_VENDORS.iter().find(|(v, _)| *v == vid).map(|(_, what)| *what)
            }
            _ => None,
        }
    }

    /// One line: the name, how it is attached (with the USB ids,
    /// manufacturer and product when known), and whether it is likely a
    /// board.
    pub fn line(&self) -> String {
        let mut s = self.name.clone();
        match &self.attachment {
            Attachment::Usb { vid, pid, manufacturer, product } => {
                let _ = write!(s, "  usb {vid:04x}:{pid:04x}");
                let what: Vec<&str> =
                    [manufacturer, product].into_iter().flatten().map(|x| x.trim()).collect();
                let what: Vec<&str> = what.into_iter().filter(|x| !x.is_empty()).collect();
                if !what.is_empty() {
                    let _ = write!(s, "  {}", what.join(" / "));
                }
            }
            Attachment::Pci => s.push_str("  pci"),
            Attachment::Bluetooth => s.push_str("  bluetooth"),
            Attachment::Unknown => s.push_str("  other"),
        }
        if let Some(what) = self.likely_board() {
            let _ = write!(s, "  <- likely board ({what})");
        }
        s
    }
}

/// The listing `isoscope-sim ports` prints: a line a port, or a plain
/// message when there are none.
pub fn listing(ports: &[PortInfo]) -> String {
    if ports.is_empty() {
        return "no serial ports found\n".to_owned();
    }
    ports.iter().map(|p| p.line() + "\n").collect()
}

/// The port `--port auto` stands for: the one likely board among
/// `ports`.
///
/// # Errors
/// No likely board, or several: the message lists the candidates (the
/// likely boards, or else every port found) and says to pass `--port
/// NAME`.
pub fn choose_auto(ports: &[PortInfo]) -> Result<&PortInfo> {
    let boards: Vec<&PortInfo> = ports.iter().filter(|p| p.likely_board().is_some()).collect();
    let names =
        |list: &[&PortInfo]| list.iter().map(|p| format!("  {}", p.line())).collect::<Vec<_>>().join("\n");
    match boards.as_slice() {
        [one] => Ok(one),
        [] if ports.is_empty() => {
            bail!("--port auto: no serial ports found; connect the board, or pass --port NAME")
        }
        [] => {
            let all: Vec<&PortInfo> = ports.iter().collect();
            bail!(
                "--port auto: none of the serial ports looks like a board (an ST-LINK or a USB-UART \
                 adapter); the ports found:\n{}\npass --port NAME",
                names(&all)
            )
        }
        several => bail!(
            "--port auto: {} serial ports look like a board:\n{}\npass --port NAME to pick one",
            several.len(),
            names(several)
        ),
    }
}

/// Sort ports by name, numbers within names by value (ttyS2 before
/// ttyS10, COM3 before COM12).
pub fn sort(ports: &mut [PortInfo]) {
    fn key(name: &str) -> (String, u64, String) {
        let stem = name.trim_end_matches(|c: char| c.is_ascii_digit());
        let n = name[stem.len()..].parse().unwrap_or(0);
        (stem.to_owned(), n, name.to_owned())
    }
    ports.sort_by_cached_key(|p| key(&p.name));
}

/// The serial ports the system knows, sorted by name.
///
/// # Errors
/// The system cannot be asked.
pub fn available() -> Result<Vec<PortInfo>> {
    // Without libudev the crate scans /sys/class/tty, and panics where
    // there is none (some containers).
    #[cfg(target_os = "linux")]
    if !std::path::Path::new("/sys/class/tty").is_dir() {
        return Ok(Vec::new());
    }
    let found =
        serialport::available_ports().map_err(|e| anyhow::anyhow!("cannot list the serial ports: {e}"))?;
    let mut ports: Vec<PortInfo> = found
        .into_iter()
        .filter(|p| present(&p.port_name))
        .map(|p| PortInfo {
            name: p.port_name,
            attachment: match p.port_type {
                serialport::SerialPortType::UsbPort(u) => Attachment::Usb {
                    vid: u.vid,
                    pid: u.pid,
                    manufacturer: u.manufacturer,
                    product: u.product,
                },
                serialport::SerialPortType::PciPort => Attachment::Pci,
                serialport::SerialPortType::BluetoothPort => Attachment::Bluetooth,
                serialport::SerialPortType::Unknown => Attachment::Unknown,
            },
        })
        .collect();
    sort(&mut ports);
    Ok(ports)
}

/// Whether a listed port is there: on Linux, a legacy 8250 port the
/// kernel set up without a UART behind it (`type` 0) is not.
fn present(name: &str) -> bool {
    #[cfg(target_os = "linux")]
    {
        let base = name.rsplit('/').next().unwrap_or(name);
        let kind = std::fs::read_to_string(format!("/sys/class/tty/{base}/type"));
        if kind.is_ok_and(|k| k.trim() == "0") {
            return false;
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = name;
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn usb(name: &str, vid: u16, pid: u16, manufacturer: Option<&str>, product: Option<&str>) -> PortInfo {
        PortInfo {
            name: name.to_owned(),
            attachment: Attachment::Usb {
                vid,
                pid,
                manufacturer: manufacturer.map(str::to_owned),
                product: product.map(str::to_owned),
            },
        }
    }

    fn other(name: &str, attachment: Attachment) -> PortInfo {
        PortInfo { name: name.to_owned(), attachment }
    }

    fn stlink() -> PortInfo {
        usb("/dev/ttyACM0", 0x0483, 0x374b, Some("STMicroelectronics"), Some("STM32 STLink"))
    }

    #[test]
    fn the_lines_say_what_each_port_is() {
        assert_eq!(
            stlink().line(),
            "/dev/ttyACM0  usb 0483:374b  STMicroelectronics / STM32 STLink  <- likely board (ST-LINK virtual COM port)"
        );
        assert_eq!(
            usb("COM4", 0x1a86, 0x7523, None, Some("USB Serial")).line(),
            "COM4  usb 1a86:7523  USB Serial  <- likely board (CH340 USB-UART)"
        );
        assert_eq!(usb("/dev/ttyACM1", 0x2341, 0x0043, None, None).line(), "/dev/ttyACM1  usb 2341:0043");
        assert_eq!(
            usb("/dev/ttyACM2", 0x2341, 0x0043, Some(" "), Some("Uno")).line(),
            "/dev/ttyACM2  usb 2341:0043  Uno"
        );
        assert_eq!(other("/dev/ttyS0", Attachment::Unknown).line(), "/dev/ttyS0  other");
        assert_eq!(other("COM1", Attachment::Pci).line(), "COM1  pci");
        assert_eq!(other("/dev/rfcomm0", Attachment::Bluetooth).line(), "/dev/rfcomm0  bluetooth");
    }

    #[test]
    fn every_likely_vendor_is_marked_and_no_other() {
        for (vid, what) in LIKELY_VENDORS {
            assert_eq!(usb("COM3", vid, 1, None, None).likely_board(), Some(what));
        }
        assert_eq!(usb("COM3", 0x2341, 1, None, None).likely_board(), None);
        assert_eq!(other("COM1", Attachment::Pci).likely_board(), None);
    }

    #[test]
    fn the_listing_is_a_line_a_port_or_a_plain_message() {
        assert_eq!(listing(&[]), "no serial ports found\n");
        let l = listing(&[other("/dev/ttyS0", Attachment::Unknown), stlink()]);
        assert_eq!(l.lines().count(), 2);
        assert!(l.starts_with("/dev/ttyS0  other\n/dev/ttyACM0  usb 0483:374b"), "{l}");
        assert!(l.ends_with('\n'));
    }

    #[test]
    fn auto_picks_the_one_board() {
        let ports = [
            other("/dev/ttyS0", Attachment::Unknown),
            stlink(),
            usb("/dev/ttyACM1", 0x2341, 0x43, None, None),
        ];
        assert_eq!(choose_auto(&ports).unwrap().name, "/dev/ttyACM0");
        let ftdi = [usb("COM7", 0x0403, 0x6001, Some("FTDI"), Some("FT232R USB UART"))];
        assert_eq!(choose_auto(&ftdi).unwrap().name, "COM7");
    }

    #[test]
    fn auto_refuses_no_port_plainly() {
        let e = choose_auto(&[]).unwrap_err().to_string();
        assert!(e.contains("no serial ports found") && e.contains("--port NAME"), "{e}");
    }

    #[test]
    fn auto_refuses_ports_none_of_which_is_a_board_and_lists_them() {
        let ports = [other("/dev/ttyS0", Attachment::Unknown), usb("/dev/ttyACM1", 0x2341, 0x43, None, None)];
        let e = choose_auto(&ports).unwrap_err().to_string();
        assert!(e.contains("none of the serial ports looks like a board"), "{e}");
        assert!(e.contains("/dev/ttyS0") && e.contains("/dev/ttyACM1") && e.contains("--port NAME"), "{e}");
    }

    #[test]
    fn auto_refuses_several_boards_and_lists_only_them() {
        let ports = [
            stlink(),
            other("/dev/ttyS0", Attachment::Unknown),
            usb(
                "/dev/ttyUSB0",
                0x10c4,
                0xea60,
                Some("Silicon Labs"),
                Some("CP2102 USB to UART Bridge Controller"),
            ),
        ];
        let e = choose_auto(&ports).unwrap_err().to_string();
        assert!(e.contains("2 serial ports look like a board"), "{e}");
        assert!(e.contains("/dev/ttyACM0") && e.contains("/dev/ttyUSB0") && !e.contains("/dev/ttyS0"), "{e}");
        assert!(e.contains("--port NAME"), "{e}");
    }

    #[test]
    fn ports_sort_by_name_with_numbers_by_value() {
        let mut ports: Vec<PortInfo> = ["COM12", "/dev/ttyS10", "COM3", "/dev/ttyS2", "/dev/ttyACM0"]
            .map(|n| other(n, Attachment::Unknown))
            .into();
        sort(&mut ports);
        let names: Vec<&str> = ports.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["/dev/ttyACM0", "/dev/ttyS2", "/dev/ttyS10", "COM3", "COM12"]);
    }

    #[test]
    fn listing_the_system_s_ports_does_not_fail() {
        let ports = available().unwrap();
        assert!(listing(&ports).ends_with('\n'));
    }
}
