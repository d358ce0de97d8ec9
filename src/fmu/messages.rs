//! An FMU's own log messages, kept per instance so a failed call can say what the FMU said.
//!
//! Each instance gets an [`Inbox`], whose address is the environment pointer the FMU passes back to
//! its logger (FMI 2.0's `componentEnvironment`, 3.0's `instanceEnvironment`): messages reach the
//! instance that logged them, whatever thread the FMU logs from. A message logged with no environment
//! (an exporter that passes NULL) goes to the calling thread's inbox instead. FMI 2.0 messages arrive
//! formatted by `logger.c`; FMI 3.0's logger is [`fdimc_fmu_log`] itself.

use std::cell::RefCell;
use std::ffi::{CStr, c_char, c_int, c_void};
use std::sync::Mutex;

/// The messages an inbox keeps: the latest, oldest first; enough for the error and what led to it.
const KEPT: usize = 8;
/// Characters kept of one message (an exporter may log a whole matrix).
const MESSAGE_CHARS: usize = 2000;

/// What one instance's FMU logged at warning level or above, since the last [`take`](Inbox::take).
#[derive(Debug, Default)]
pub struct Inbox {
    said: Mutex<Vec<String>>,
}

impl Inbox {
    /// The environment pointer the FMU is given (valid while the boxed inbox lives).
    pub fn environment(&self) -> *mut c_void {
        (self as *const Inbox).cast_mut().cast()
    }

    fn keep(&self, text: String) {
        let mut said = self.said.lock().unwrap_or_else(|e| e.into_inner());
        if said.len() == KEPT {
            said.remove(0);
        }
        said.push(text);
    }

    /// What the FMU said since the last call (and this thread's messages logged without an
    /// environment), joined, or `None`; forgets it.
    pub fn take(&self) -> Option<String> {
        let mut said = std::mem::take(&mut *self.said.lock().unwrap_or_else(|e| e.into_inner()));
        said.extend(STRAY.with(|s| std::mem::take(&mut *s.borrow_mut())));
        (!said.is_empty()).then(|| said.join(" | "))
    }

    /// Forgets what was said (before a call whose messages are wanted).
    pub fn clear(&self) {
        self.said.lock().unwrap_or_else(|e| e.into_inner()).clear();
        STRAY.with(|s| s.borrow_mut().clear());
    }
}

thread_local! {
    /// Messages logged with a NULL environment on this thread.
    static STRAY: RefCell<Vec<String>> = const { RefCell::new(Vec::new()) };
}

fn status_name(status: c_int) -> &'static str {
    // FMI 2.0 and 3.0 number OK to Fatal alike; 2.0 adds Pending.
    match status {
        0 => "OK",
        1 => "Warning",
        2 => "Discard",
        3 => "Error",
        4 => "Fatal",
        5 => "Pending",
        _ => "unknown status",
    }
}

/// The FMU's logger: keeps warnings and worse in the instance's inbox. Never unwinds into the FMU.
///
/// # Safety
/// `environment` is NULL or an [`Inbox::environment`] pointer of a live inbox; `category` and
/// `message` are NULL or NUL-terminated strings.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fdimc_fmu_log(
    environment: *mut c_void,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    if status == 0 {
        return;
    }
    let text = |p: *const c_char| {
        // SAFETY: the FMU passes NUL-terminated strings or NULL (checked).
        (!p.is_null()).then(|| unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned())
    };
    let _ = std::panic::catch_unwind(|| {
        let mut line = format!("[{}", status_name(status));
        if let Some(c) = text(category).filter(|c| !c.is_empty()) {
            line += &format!(" {c}");
        }
        line += "] ";
        line += text(message).as_deref().unwrap_or("(no message)").trim_end();
        if line.chars().count() > MESSAGE_CHARS {
            line = line.chars().take(MESSAGE_CHARS).collect::<String>() + "...";
        }
        if environment.is_null() {
            STRAY.with(|s| {
                let mut s = s.borrow_mut();
                if s.len() == KEPT {
                    s.remove(0);
                }
                s.push(line);
            });
        } else {
            // SAFETY: a live inbox's address, as the instance gave it.
            unsafe { &*(environment as *const Inbox) }.keep(line);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_reach_their_instance_and_info_is_dropped() {
        let (a, b) = (Box::new(Inbox::default()), Box::new(Inbox::default()));
        let say = |inbox: &Inbox, status, msg: &std::ffi::CStr| unsafe {
            fdimc_fmu_log(inbox.environment(), status, c"logStatusError".as_ptr(), msg.as_ptr())
        };
        say(&a, 3, c"division by zero at t = 1");
        say(&b, 1, c"step size reduced");
        say(&a, 0, c"an info line");
        assert_eq!(a.take().as_deref(), Some("[Error logStatusError] division by zero at t = 1"));
        assert_eq!(a.take(), None);
        assert_eq!(b.take().as_deref(), Some("[Warning logStatusError] step size reduced"));
        // NULL environment, category and message: kept on this thread.
        unsafe { fdimc_fmu_log(std::ptr::null_mut(), 4, std::ptr::null(), std::ptr::null()) };
        assert_eq!(a.take().as_deref(), Some("[Fatal] (no message)"));
        for k in 0..20 {
            say(&a, 2, &std::ffi::CString::new(format!("m{k}")).unwrap());
        }
        let kept = a.take().unwrap();
        assert!(kept.starts_with("[Discard logStatusError] m12 |") && kept.ends_with("m19"), "{kept}");
    }

    #[test]
    fn the_c_logger_formats_its_arguments() {
        let inbox = Box::new(Inbox::default());
        unsafe {
            crate::fmu::ffi::fdimc_fmi2_logger(
                inbox.environment(),
                c"inst".as_ptr(),
                3,
                c"logStatusError".as_ptr(),
                c"x = %g after %d steps: %s".as_ptr(),
                2.5f64,
                7 as c_int,
                c"diverged".as_ptr(),
            )
        };
        assert_eq!(inbox.take().as_deref(), Some("[Error logStatusError] x = 2.5 after 7 steps: diverged"));
        let long = "y".repeat(5000);
        let long = std::ffi::CString::new(long).unwrap();
        unsafe {
            crate::fmu::ffi::fdimc_fmi2_logger(
                inbox.environment(),
                c"inst".as_ptr(),
                1,
                c"".as_ptr(),
                c"%s".as_ptr(),
                long.as_ptr(),
            )
        };
        let kept = inbox.take().unwrap();
        assert!(kept.starts_with("[Warning] yyy") && kept.ends_with("y..."), "{}", &kept[..40]);
        assert_eq!(kept.chars().count(), MESSAGE_CHARS + 3);
    }
}
