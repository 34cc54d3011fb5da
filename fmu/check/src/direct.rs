//! A direct Rust import of a packed FMU: the archive unpacked to a temporary folder, its
//! shared library opened with `libloading` and driven through the FMI 3.0 C functions by
//! name, as a co-simulation master does (nothing of the FMU's own code is linked).

use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::path::Path;
use std::sync::Mutex;

use anyhow::{Context, Result, anyhow, bail};

use crate::description::Description;

/// `fmi3OK`, `fmi3Warning`, `fmi3Error`.
pub const OK: c_int = 0;
pub const WARNING: c_int = 1;
pub const ERROR: c_int = 3;

type LogFn = unsafe extern "C" fn(*mut c_void, c_int, *const c_char, *const c_char);
type InstantiateFn = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    bool,
    bool,
    *const u32,
    usize,
    *mut c_void,
    Option<LogFn>,
    *const c_void,
) -> *mut c_void;
type FreeFn = unsafe extern "C" fn(*mut c_void);
type EnterInitFn = unsafe extern "C" fn(*mut c_void, bool, f64, f64, bool, f64) -> c_int;
type ModeFn = unsafe extern "C" fn(*mut c_void) -> c_int;
type SetF64Fn = unsafe extern "C" fn(*mut c_void, *const u32, usize, *const f64, usize) -> c_int;
type GetF64Fn = unsafe extern "C" fn(*mut c_void, *const u32, usize, *mut f64, usize) -> c_int;
type SetI64Fn = unsafe extern "C" fn(*mut c_void, *const u32, usize, *const i64, usize) -> c_int;
type GetBoolFn = unsafe extern "C" fn(*mut c_void, *const u32, usize, *mut bool, usize) -> c_int;
type SetStringFn =
    unsafe extern "C" fn(*mut c_void, *const u32, usize, *const *const c_char, usize) -> c_int;
type DoStepFn = unsafe extern "C" fn(
    *mut c_void,
    f64,
    f64,
    bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut f64,
) -> c_int;

/// The FMI functions this importer calls.
#[derive(Clone, Copy)]
struct Functions {
    instantiate: InstantiateFn,
    free: FreeFn,
    enter_init: EnterInitFn,
    exit_init: ModeFn,
    terminate: ModeFn,
    set_f64: SetF64Fn,
    get_f64: GetF64Fn,
    set_i64: SetI64Fn,
    get_bool: GetBoolFn,
    set_string: SetStringFn,
    do_step: DoStepFn,
}

/// An unpacked FMU with its library loaded.
pub struct Fmu {
    pub description: Description,
    functions: Functions,
    resources: CString,
    _library: libloading::Library,
    dir: tempfile::TempDir,
}

/// The FMI platform folder and library suffix of this machine.
fn platform() -> Result<String> {
    use std::env::consts::{ARCH, OS};
    let os = match OS {
        "linux" => "linux",
        "windows" => "windows",
        "macos" => "darwin",
        other => bail!("no FMI platform for {other}"),
    };
    Ok(format!("{ARCH}-{os}"))
}

impl Fmu {
    /// Unpacks `path` and loads the library of this platform.
    pub fn open(path: &Path) -> Result<Self> {
        let dir = tempfile::tempdir()?;
        let file =
            std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
        zip::ZipArchive::new(file)?
            .extract(dir.path())
            .with_context(|| format!("cannot unpack {}", path.display()))?;
        let xml = std::fs::read_to_string(dir.path().join("modelDescription.xml"))?;
        let description = Description::parse(&xml)?;
        let library = dir.path().join("binaries").join(platform()?).join(format!(
            "{}{}",
            description.model_identifier,
            std::env::consts::DLL_SUFFIX
        ));
        // SAFETY: loading the FMU's library runs no initialisers of ours beyond the
        // standard's (it is a Rust cdylib without constructors).
        let library = unsafe { libloading::Library::new(&library) }
            .with_context(|| format!("cannot load {}", library.display()))?;
        // SAFETY: the symbols have the FMI 3.0 signatures of fmi3FunctionTypes.h.
        let functions = unsafe {
            Functions {
                instantiate: *library.get(b"fmi3InstantiateCoSimulation")?,
                free: *library.get(b"fmi3FreeInstance")?,
                enter_init: *library.get(b"fmi3EnterInitializationMode")?,
                exit_init: *library.get(b"fmi3ExitInitializationMode")?,
                terminate: *library.get(b"fmi3Terminate")?,
                set_f64: *library.get(b"fmi3SetFloat64")?,
                get_f64: *library.get(b"fmi3GetFloat64")?,
                set_i64: *library.get(b"fmi3SetInt64")?,
                get_bool: *library.get(b"fmi3GetBoolean")?,
                set_string: *library.get(b"fmi3SetString")?,
                do_step: *library.get(b"fmi3DoStep")?,
            }
        };
        let resources = CString::new(format!("{}/", dir.path().join("resources").display()))?;
        Ok(Fmu {
            description,
            functions,
            resources,
            _library: library,
            dir,
        })
    }

    /// A new instance (its messages kept).
    pub fn instantiate(&self, name: &str) -> Result<Instance<'_>> {
        let log: Box<Log> = Box::new(Mutex::new(Vec::new()));
        let name_c = CString::new(name)?;
        let token = CString::new(self.description.token.as_str())?;
        // SAFETY: valid strings, a logger that outlives the instance (boxed, dropped after
        // fmi3FreeInstance).
        let ptr = unsafe {
            (self.functions.instantiate)(
                name_c.as_ptr(),
                token.as_ptr(),
                self.resources.as_ptr(),
                false,
                false,
                false,
                false,
                std::ptr::null(),
                0,
                &*log as *const Log as *mut c_void,
                Some(log_message),
                std::ptr::null(),
            )
        };
        if ptr.is_null() {
            bail!(
                "fmi3InstantiateCoSimulation failed: {:?}",
                log.lock().map(|l| l.clone())
            );
        }
        Ok(Instance {
            fmu: self,
            ptr,
            log,
        })
    }

    /// The unpacked `resources/` folder.
    pub fn resources_dir(&self) -> Option<String> {
        Some(self.dir.path().join("resources").display().to_string())
    }

    /// The value reference of a variable.
    pub fn vr(&self, name: &str) -> Result<u32> {
        Ok(self.description.var(name)?.vr)
    }
}

/// Messages an instance logged: (status, message).
type Log = Mutex<Vec<(c_int, String)>>;

unsafe extern "C" fn log_message(
    env: *mut c_void,
    status: c_int,
    _category: *const c_char,
    message: *const c_char,
) {
    // SAFETY: `env` is the instance's boxed log; `message` NUL-terminated (FMI contract).
    let log = unsafe { &*(env as *const Log) };
    let text = unsafe { CStr::from_ptr(message) }
        .to_string_lossy()
        .into_owned();
    if let Ok(mut l) = log.lock() {
        l.push((status, text));
    }
}

/// One instance of a loaded FMU.
pub struct Instance<'a> {
    fmu: &'a Fmu,
    ptr: *mut c_void,
    log: Box<Log>,
}

impl Instance<'_> {
    fn f(&self) -> &Functions {
        &self.fmu.functions
    }

    /// The messages logged so far.
    pub fn messages(&self) -> Vec<(c_int, String)> {
        self.log.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// The last message logged (empty if none).
    pub fn last_message(&self) -> String {
        self.messages()
            .last()
            .map(|m| m.1.clone())
            .unwrap_or_default()
    }

    fn check(&self, call: &str, status: c_int) -> Result<c_int> {
        if status > WARNING {
            bail!("{call}: status {status}: {}", self.last_message());
        }
        Ok(status)
    }

    pub fn set_f64(&mut self, vrs: &[u32], values: &[f64]) -> c_int {
        // SAFETY: arrays of the given lengths.
        unsafe {
            (self.f().set_f64)(
                self.ptr,
                vrs.as_ptr(),
                vrs.len(),
                values.as_ptr(),
                values.len(),
            )
        }
    }

    pub fn get_f64(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<()> {
        // SAFETY: arrays of the given lengths.
        let s = unsafe {
            (self.f().get_f64)(
                self.ptr,
                vrs.as_ptr(),
                vrs.len(),
                values.as_mut_ptr(),
                values.len(),
            )
        };
        self.check("fmi3GetFloat64", s).map(|_| ())
    }

    pub fn get_bool(&mut self, vrs: &[u32], values: &mut [bool]) -> Result<()> {
        // SAFETY: arrays of the given lengths.
        let s = unsafe {
            (self.f().get_bool)(
                self.ptr,
                vrs.as_ptr(),
                vrs.len(),
                values.as_mut_ptr(),
                values.len(),
            )
        };
        self.check("fmi3GetBoolean", s).map(|_| ())
    }

    pub fn set_i64(&mut self, name: &str, value: i64) -> Result<c_int> {
        let vr = self.fmu.vr(name)?;
        // SAFETY: one value.
        Ok(unsafe { (self.f().set_i64)(self.ptr, &vr, 1, &value, 1) })
    }

    pub fn set_string(&mut self, name: &str, value: &str) -> Result<c_int> {
        let vr = self.fmu.vr(name)?;
        let value = CString::new(value)?;
        let p = value.as_ptr();
        // SAFETY: one value.
        Ok(unsafe { (self.f().set_string)(self.ptr, &vr, 1, &p, 1) })
    }

    pub fn set_by_name(&mut self, name: &str, value: f64) -> Result<c_int> {
        let vr = self.fmu.vr(name)?;
        Ok(self.set_f64(&[vr], &[value]))
    }

    /// Enters and leaves initialisation at t = 0 (no stop time).
    pub fn initialize(&mut self) -> Result<()> {
        // SAFETY: the instance pointer.
        let s = unsafe { (self.f().enter_init)(self.ptr, false, 0.0, 0.0, false, 0.0) };
        self.check("fmi3EnterInitializationMode", s)?;
        let s = unsafe { (self.f().exit_init)(self.ptr) };
        self.check("fmi3ExitInitializationMode", s).map(|_| ())
    }

    /// `fmi3EnterInitializationMode` alone (for out-of-order checks).
    pub fn enter_initialization(&mut self) -> c_int {
        // SAFETY: the instance pointer.
        unsafe { (self.f().enter_init)(self.ptr, false, 0.0, 0.0, false, 0.0) }
    }

    pub fn step(&mut self, t: f64, h: f64) -> c_int {
        let (mut a, mut b, mut c, mut last) = (false, false, false, 0.0);
        // SAFETY: the instance pointer and four out-arguments.
        unsafe { (self.f().do_step)(self.ptr, t, h, true, &mut a, &mut b, &mut c, &mut last) }
    }

    pub fn terminate(&mut self) -> c_int {
        // SAFETY: the instance pointer.
        unsafe { (self.f().terminate)(self.ptr) }
    }
}

impl Drop for Instance<'_> {
    fn drop(&mut self) {
        // SAFETY: freed once, before its log.
        unsafe { (self.f().free)(self.ptr) };
    }
}

/// The value references and names of the Float64 and Boolean outputs.
pub struct Outputs {
    pub floats: Vec<u32>,
    pub float_names: Vec<String>,
    pub bools: Vec<u32>,
    pub bool_names: Vec<String>,
}

impl Outputs {
    pub fn of(fmu: &Fmu) -> Self {
        let d = &fmu.description;
        let pick = |kind: &str| -> (Vec<u32>, Vec<String>) {
            d.outputs(kind)
                .iter()
                .map(|v| (v.vr, v.name.clone()))
                .unzip()
        };
        let (floats, float_names) = pick("Float64");
        let (bools, bool_names) = pick("Boolean");
        Outputs {
            floats,
            float_names,
            bools,
            bool_names,
        }
    }

    /// Reads every output as f64 (Booleans as 0/1), names in `names()` order.
    pub fn read(&self, inst: &mut Instance<'_>, out: &mut Vec<f64>) -> Result<()> {
        out.resize(self.floats.len(), 0.0);
        inst.get_f64(&self.floats, out)?;
        let mut b = vec![false; self.bools.len()];
        inst.get_bool(&self.bools, &mut b)?;
        out.extend(b.iter().map(|&x| if x { 1.0 } else { 0.0 }));
        Ok(())
    }

    pub fn names(&self) -> Vec<String> {
        self.float_names
            .iter()
            .chain(&self.bool_names)
            .cloned()
            .collect()
    }
}

/// A refused call must return `fmi3Error` and log a message containing `needle`.
pub fn expect_refusal(
    inst: &Instance<'_>,
    what: &str,
    status: c_int,
    needle: &str,
) -> Result<String> {
    let message = inst.last_message();
    if status != ERROR {
        return Err(anyhow!("{what}: status {status}, expected fmi3Error"));
    }
    if !message.contains(needle) {
        return Err(anyhow!(
            "{what}: logged `{message}`, expected a message with `{needle}`"
        ));
    }
    Ok(message)
}
