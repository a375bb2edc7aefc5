//! The virtual board on TCP outlives its clients: one that resets the
//! connection mid-transfer, one that idles, one that trickles bytes; and a
//! sender that finds it serving another client is told it is busy.

use isoscope_core::wire::{Message, PROTOCOL_VERSION, encode};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_isoscope-sim")
}

/// A virtual board on a free TCP port; its log lines arrive on `lines`.
struct Board {
    child: Child,
    addr: String,
    lines: Receiver<String>,
}

impl Board {
    fn start(extra: &[&str]) -> Self {
        let mut child = Command::new(bin())
            .args(["device", "--tcp", "127.0.0.1:0", "--baud", "0"])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let (tx, lines) = channel();
        let out = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    return;
                }
            }
        });
        let addr = lines.recv_timeout(Duration::from_secs(10)).unwrap();
        Self { child, addr, lines }
    }

    /// Wait for a log line containing `word`.
    fn expect(&self, word: &str) -> String {
        let deadline = Instant::now() + Duration::from_secs(20);
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.lines.recv_timeout(left) {
                Ok(l) if l.contains(word) => return l,
                Ok(_) => {}
                Err(_) => break,
            }
        }
        panic!("no `{word}` in the board's log");
    }

    fn alive(&mut self) -> bool {
        self.child.try_wait().unwrap().is_none()
    }

    fn send(&self, extra: &[&str]) -> std::process::Output {
        let port = format!("tcp:{}", self.addr);
        Command::new(bin())
            .args(["send", "--demo", "torus:12", "--port", &port])
            .args(extra)
            .output()
            .unwrap()
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn frame(msg: &Message<'_>) -> Vec<u8> {
    let mut buf = [0u8; 2048];
    encode(msg, &mut buf).unwrap().to_vec()
}

fn ok(out: &std::process::Output) -> bool {
    out.status.success()
}

#[test]
fn a_client_that_resets_mid_transfer_leaves_the_board_serving() {
    let mut board = Board::start(&[]);
    // Hello, a volume begun and half a slice, then gone with the answers
    // unread: the kernel resets the connection.
    let mut rude = TcpStream::connect(&board.addr).unwrap();
    rude.write_all(&frame(&Message::Hello { protocol: PROTOCOL_VERSION, firmware: [0; 3], seq: 7 })).unwrap();
    let begin = Message::BeginVolume {
        seq: 7,
        dims: [12, 12, 12],
        sample_type: isoscope_core::wire::SampleType::U8,
        spacing: [1.0; 3],
        levels: isoscope_core::wire::Levels::from_slice(&[0.5]).unwrap(),
        axes: isoscope_core::wire::AXIS_X,
        every: 1,
    };
    rude.write_all(&frame(&begin)).unwrap();
    rude.write_all(&frame(&Message::SliceData { seq: 8, slice: 0, offset: 0, data: &[0u8; 60] })).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    drop(rude);
    board.expect("begun");
    let out = board.send(&[]);
    assert!(ok(&out), "send after a reset failed: {}", String::from_utf8_lossy(&out.stderr));
    assert!(board.alive(), "the board exited");
    board.expect("redrawn");
}

#[test]
fn a_second_sender_is_told_the_board_is_busy_and_an_idle_client_is_dropped() {
    let mut board = Board::start(&["--idle-timeout", "2"]);
    // A client that connects and says nothing holds the board...
    let idle = TcpStream::connect(&board.addr).unwrap();
    board.expect("connected");
    let out = board.send(&[]);
    assert!(!ok(&out));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("busy with another client"), "{err}");
    // ...until the idle timeout drops it (the board logs the sender it
    // turned away meanwhile after that); then the next sender gets through.
    board.expect("dropped");
    board.expect("turned away");
    let out = board.send(&[]);
    assert!(ok(&out), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(board.alive());
    drop(idle);
}

#[test]
fn a_trickling_client_is_dropped_too() {
    let mut board = Board::start(&["--idle-timeout", "1"]);
    let mut slow = TcpStream::connect(&board.addr).unwrap();
    board.expect("connected");
    // A byte every 200 ms, never a whole frame.
    let hello = frame(&Message::Hello { protocol: PROTOCOL_VERSION, firmware: [0; 3], seq: 7 });
    let t0 = Instant::now();
    let mut dropped = false;
    for &b in hello.iter().take(hello.len() - 1).cycle().take(20) {
        if slow.write_all(&[b]).is_err() {
            dropped = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(200));
        let mut peek = [0u8; 1];
        slow.set_nonblocking(true).unwrap();
        if let Ok(0) = slow.read(&mut peek) {
            dropped = true;
            break;
        }
        slow.set_nonblocking(false).unwrap();
    }
    assert!(dropped, "the trickling client was kept for {:?}", t0.elapsed());
    board.expect("dropped");
    assert!(board.alive());
    let out = board.send(&[]);
    assert!(ok(&out), "{}", String::from_utf8_lossy(&out.stderr));
}
