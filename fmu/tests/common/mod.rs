//! A small FMI 3.0 importer over the FMU's C functions (linked from the rlib: the same code
//! the shared library exports), for the tests: instantiate with a logger that keeps every
//! message, set and get by name, step.
#![allow(dead_code, missing_docs)]

use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use hils_fmu::abi::*;
use hils_fmu::variables::{self, Variable};

pub const OK: c_int = 0;
pub const WARNING: c_int = 1;
pub const ERROR: c_int = 3;

/// Messages logged by one instance: (status, category, message).
pub type Log = Mutex<Vec<(c_int, String, String)>>;

unsafe extern "C" fn logger(
    env: *mut c_void,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    let log = unsafe { &*(env as *const Log) };
    let text = |p: *const c_char| unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned();
    log.lock()
        .unwrap()
        .push((status, text(category), text(message)));
}

/// The resources folder of a test: `parameters.toml` of `file`'s values.
pub fn resources(tag: &str, file: &hils_sil::ParamFile) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hils-fmu-test-{}-{tag}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join(hils_fmu::RESOURCE_FILE),
        hils_fmu::description::parameter_file(file, "a test"),
    )
    .unwrap();
    dir
}

pub struct Fmu {
    pub ptr: *mut c_void,
    pub log: Box<Log>,
}

pub fn var(name: &str) -> &'static Variable {
    variables::by_name(name).unwrap_or_else(|| panic!("no variable {name}"))
}

impl Fmu {
    /// Instantiates with the given resources folder (None: a NULL resource path) and token.
    pub fn with(resources: Option<&Path>, token: &str, logging_on: bool) -> Self {
        let log: Box<Log> = Box::new(Mutex::new(Vec::new()));
        let name = CString::new("test").unwrap();
        let token = CString::new(token).unwrap();
        let path = resources.map(|p| CString::new(format!("{}/", p.display())).unwrap());
        let ptr = unsafe {
            fmi3InstantiateCoSimulation(
                name.as_ptr(),
                token.as_ptr(),
                path.as_ref().map_or(std::ptr::null(), |p| p.as_ptr()),
                0,
                u8::from(logging_on),
                0,
                0,
                std::ptr::null(),
                0,
                &*log as *const Log as *mut c_void,
                Some(logger),
                std::ptr::null(),
            )
        };
        Fmu { ptr, log }
    }

    pub fn new(resources: &Path) -> Self {
        let f = Self::with(
            Some(resources),
            &hils_fmu::description::instantiation_token(),
            false,
        );
        assert!(!f.ptr.is_null(), "instantiation failed: {:?}", f.messages());
        f
    }

    pub fn messages(&self) -> Vec<(c_int, String, String)> {
        self.log.lock().unwrap().clone()
    }

    /// The last message logged.
    pub fn last(&self) -> String {
        self.log
            .lock()
            .unwrap()
            .last()
            .map(|m| m.2.clone())
            .unwrap_or_default()
    }

    pub fn set_f64(&self, name: &str, x: f64) -> c_int {
        let vr = var(name).vr;
        unsafe { fmi3SetFloat64(self.ptr, &vr, 1, &x, 1) }
    }

    pub fn get_f64(&self, name: &str) -> f64 {
        let vr = var(name).vr;
        let mut x = f64::NAN;
        let s = unsafe { fmi3GetFloat64(self.ptr, &vr, 1, &mut x, 1) };
        assert_eq!(s, OK, "get {name}: {}", self.last());
        x
    }

    pub fn get_many(&self, vrs: &[u32], out: &mut [f64]) {
        let s = unsafe {
            fmi3GetFloat64(
                self.ptr,
                vrs.as_ptr(),
                vrs.len(),
                out.as_mut_ptr(),
                out.len(),
            )
        };
        assert_eq!(s, OK, "{}", self.last());
    }

    pub fn set_i64(&self, name: &str, x: i64) -> c_int {
        let vr = var(name).vr;
        unsafe { fmi3SetInt64(self.ptr, &vr, 1, &x, 1) }
    }

    pub fn set_u32(&self, name: &str, x: u32) -> c_int {
        let vr = var(name).vr;
        unsafe { fmi3SetUInt32(self.ptr, &vr, 1, &x, 1) }
    }

    pub fn get_bool(&self, name: &str) -> bool {
        let vr = var(name).vr;
        let mut b = 7u8;
        let s = unsafe { fmi3GetBoolean(self.ptr, &vr, 1, &mut b, 1) };
        assert_eq!(s, OK, "{}", self.last());
        b != 0
    }

    pub fn get_u32(&self, name: &str) -> u32 {
        let vr = var(name).vr;
        let mut x = 0u32;
        let s = unsafe { fmi3GetUInt32(self.ptr, &vr, 1, &mut x, 1) };
        assert_eq!(s, OK, "{}", self.last());
        x
    }

    pub fn set_string(&self, name: &str, s: &str) -> c_int {
        let vr = var(name).vr;
        let s = CString::new(s).unwrap();
        let p = s.as_ptr();
        unsafe { fmi3SetString(self.ptr, &vr, 1, &p, 1) }
    }

    pub fn enter_init(&self) -> c_int {
        unsafe { fmi3EnterInitializationMode(self.ptr, 0, 0.0, 0.0, 0, 0.0) }
    }

    pub fn exit_init(&self) -> c_int {
        unsafe { fmi3ExitInitializationMode(self.ptr) }
    }

    /// Enter and exit initialisation; panics with the log on a refusal.
    pub fn init(&self) {
        assert_eq!(self.enter_init(), OK, "{}", self.last());
        assert_eq!(self.exit_init(), OK, "{}", self.last());
    }

    pub fn step(&self, t: f64, h: f64) -> c_int {
        let (mut a, mut b, mut c, mut last) = (0u8, 0u8, 0u8, 0.0);
        unsafe { fmi3DoStep(self.ptr, t, h, 1, &mut a, &mut b, &mut c, &mut last) }
    }
}

impl Drop for Fmu {
    fn drop(&mut self) {
        unsafe { fmi3FreeInstance(self.ptr) };
    }
}
