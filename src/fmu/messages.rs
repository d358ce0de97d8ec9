//! An FMU's own log messages, kept so a failed trial can say what the FMU said.
//!
//! The `fmi` crate hands the FMU's logger callback to the `log` facade, on the thread that made the FMI
//! call. fdimc installs a `log::Log` that keeps the latest warning or error per thread; an FMI call that
//! fails takes it with [`take_last`]. Messages from fdimc's own crates pass through untouched (none are
//! logged today).

use std::cell::RefCell;
use std::sync::Once;

thread_local! {
    static LAST: RefCell<Option<String>> = const { RefCell::new(None) };
}

struct Keeper;

impl log::Log for Keeper {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::Level::Warn
    }
    fn log(&self, record: &log::Record) {
        if record.module_path() == Some("logger") && self.enabled(record.metadata()) {
            let text = format!("{}: {}", record.target(), record.args());
            LAST.with(|l| *l.borrow_mut() = Some(text));
        }
    }
    fn flush(&self) {}
}

static KEEPER: Keeper = Keeper;
static INSTALL: Once = Once::new();

/// Installs the keeper once per process (a host that set its own logger keeps it).
pub fn install() {
    INSTALL.call_once(|| {
        if log::set_logger(&KEEPER).is_ok() {
            log::set_max_level(log::LevelFilter::Warn);
        }
    });
}

/// Forgets this thread's last message (before a call whose message is wanted).
pub fn clear() {
    LAST.with(|l| l.borrow_mut().take());
}

/// This thread's latest FMU warning or error, if any, and forgets it.
pub fn take_last() -> Option<String> {
    LAST.with(|l| l.borrow_mut().take())
}
