//! pty loopback: the core device session on one end of a pseudo-terminal pair
//! (`serialport::TTYPort::pair`), the host client on the other — the real serial-port
//! code path without hardware.
#![cfg(unix)]

use activesense_core::device::{ServeEnd, Session};
use activesense_instrument::link::device::{serve_std, HOST_DEVICE};
use activesense_instrument::link::serial::Client;
use activesense_tests::{check_episodes, fault_suite};
use serialport::{SerialPort, TTYPort};
use std::time::Duration;

#[test]
fn pty_episodes_and_faults() {
    let (mut master, mut slave) = TTYPort::pair().expect("pty pair");
    master.set_timeout(Duration::from_secs(5)).unwrap();
    slave.set_timeout(Duration::from_millis(20)).unwrap();
    let device = std::thread::spawn(move || {
        let mut session = Box::new(Session::new(HOST_DEVICE));
        let end = serve_std(&mut session, &mut slave).expect("serve");
        // Keep the slave open until the host has read the last reply: serialport reports
        // POLLIN|POLLHUP on the master as a broken pipe even with data pending.
        (end, slave)
    });
    let mut c = Client::new(master);
    c.hello().unwrap();
    assert!(check_episodes(&mut c, 3, 1) > 0);
    assert!(check_episodes(&mut c, 3, 10) > 0);
    fault_suite(&mut c);
    c.shutdown().unwrap();
    let (end, slave) = device.join().unwrap();
    assert_eq!(end, ServeEnd::Shutdown);
    drop(slave);
}
