//! The FMI 3.0 C API (`fmi3Functions.h`, Co-Simulation) over [`Model`]: every function of
//! the standard's headers is exported (those of Model Exchange and Scheduled Execution
//! refuse with a logged message). Each call checks its pointers and counts, runs inside
//! `catch_unwind` (no panic crosses the C boundary: one would leave the instance refusing
//! further calls, logged), and logs every refusal through the importer's `logMessage`
//! callback, whatever the debug-logging setting (FMI 3.0: errors are always reported).
//! Instances share nothing: any number run side by side in one process.
#![allow(non_snake_case, missing_docs, clippy::missing_safety_doc)]

use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::sync::Mutex;

use crate::description::LOG_CATEGORIES;
use crate::instance::{Fault, Model, Outcome, Status, fault, variable};

/// `fmi3LogMessageCallback`.
pub type LogMessage = unsafe extern "C" fn(
    instance_environment: *mut c_void,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
);

const ERROR: c_int = Status::Error as c_int;

/// Marks a live instance (a freed or foreign pointer is refused when it no longer holds it).
const MAGIC: u64 = 0x6869_6c73_666d_7533; // "hilsfmu3"
const STATE_MAGIC: u64 = 0x6869_6c73_7374_6174; // "hilsstat"

/// The addresses of the instances alive: `fmi3FreeInstance` frees only one of these, so a
/// pointer freed already (an importer freeing twice) or a foreign one is left alone without
/// reading its memory (the magic word of the other calls is read from the pointer).
static LIVE: Mutex<Vec<usize>> = Mutex::new(Vec::new());

/// Takes `instance` out of [`LIVE`]; false if it was not there.
fn take_live(instance: *mut c_void) -> bool {
    let mut live = LIVE.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    match live.iter().position(|&p| p == instance as usize) {
        Some(i) => {
            live.swap_remove(i);
            true
        }
        None => false,
    }
}

/// The importer's logger and the debug-logging settings.
struct Logger {
    callback: Option<LogMessage>,
    environment: *mut c_void,
    debug: bool,
    categories: [bool; LOG_CATEGORIES.len()],
}

impl Logger {
    /// Sends a message: errors and warnings always, the others (category index `category`)
    /// when debug logging is on for it.
    fn log(&self, status: Status, category: usize, message: &str) {
        let Some(callback) = self.callback else {
            return;
        };
        let always = status >= Status::Warning;
        if !always && !(self.debug && self.categories.get(category).copied().unwrap_or(false)) {
            return;
        }
        let category = LOG_CATEGORIES
            .get(category)
            .map_or("logEvents", |(name, _)| name);
        let text = |s: &str| CString::new(s.replace('\0', " ")).unwrap_or_default();
        let (category, message) = (text(category), text(message));
        // SAFETY: the importer's callback, with NUL-terminated strings valid for the call.
        unsafe {
            callback(
                self.environment,
                status as c_int,
                category.as_ptr(),
                message.as_ptr(),
            )
        };
    }
}

/// An FMU instance as the C API sees it (`repr(C)`: the magic first, read before the
/// pointer is taken for an instance).
#[repr(C)]
pub struct Instance {
    magic: u64,
    name: String,
    logger: Logger,
    model: Model,
    /// Strings handed out by the last `fmi3GetString` (valid until the next call).
    strings: Vec<CString>,
    /// A panic was caught in a call: only reset and free are accepted.
    broken: Option<String>,
}

const CATEGORY_ERROR: usize = 0;
const CATEGORY_WARNING: usize = 1;
const CATEGORY_EVENTS: usize = 2;

impl Instance {
    fn error(&self, call: &str, message: &str) {
        self.logger.log(
            Status::Error,
            CATEGORY_ERROR,
            &format!("{} ({call}): {message}", self.name),
        );
    }

    fn event(&self, message: &str) {
        self.logger.log(
            Status::Ok,
            CATEGORY_EVENTS,
            &format!("{}: {message}", self.name),
        );
    }

    fn warning(&self, message: &str) {
        self.logger.log(
            Status::Warning,
            CATEGORY_WARNING,
            &format!("{}: {message}", self.name),
        );
    }
}

/// The instance behind a pointer, if it is one of ours and alive.
///
/// # Safety
/// `instance` is null or a pointer `fmi3InstantiateCoSimulation` returned.
unsafe fn instance_of<'a>(instance: *mut c_void) -> Option<&'a mut Instance> {
    if instance.is_null() || !instance.cast::<u64>().is_aligned() {
        return None;
    }
    // SAFETY: a non-null pointer the importer passes is readable (FMI contract); only the
    // first word is read until it proves to be an instance of ours (a pointer freed by
    // fmi3FreeInstance or a foreign one is refused while its memory holds no magic).
    if unsafe { instance.cast::<u64>().read() } != MAGIC {
        return None;
    }
    // SAFETY: the magic is only ever written by fmi3InstantiateCoSimulation's Box.
    unsafe { (instance as *mut Instance).as_mut() }
}

/// Runs `f` on the instance: checks the pointer, catches a panic, logs a refusal.
fn call(
    instance: *mut c_void,
    name: &'static str,
    f: impl FnOnce(&mut Instance) -> Outcome,
) -> c_int {
    // SAFETY: the FMI contract on `instance` (see `instance_of`).
    let Some(inst) = (unsafe { instance_of(instance) }) else {
        return ERROR;
    };
    if let Some(cause) = &inst.broken
        && name != "fmi3Reset"
    {
        inst.error(
            name,
            &format!("the instance failed in an earlier call ({cause}); reset or free it"),
        );
        return ERROR;
    }
    match catch_unwind(AssertUnwindSafe(|| f(&mut *inst))) {
        Ok(Ok(status)) => status as c_int,
        Ok(Err(Fault(message))) => {
            inst.error(name, &message);
            ERROR
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            let cause = format!("internal error in {name}: {what}");
            inst.error(name, &cause);
            inst.broken = Some(cause);
            ERROR
        }
    }
}

/// A C array as a slice (empty for a count of 0, refused for a null pointer with a count).
///
/// # Safety
/// A non-null `p` points to `n` valid values (the FMI contract).
unsafe fn slice<'a, T>(p: *const T, n: usize, what: &str) -> Result<&'a [T], Fault> {
    if n == 0 {
        return Ok(&[]);
    }
    if p.is_null() {
        return fault(format!("{what} is NULL with {n} elements"));
    }
    // SAFETY: non-null, n elements (caller's contract).
    Ok(unsafe { std::slice::from_raw_parts(p, n) })
}

/// As [`slice`], mutable.
///
/// # Safety
/// A non-null `p` points to `n` writable values.
unsafe fn slice_mut<'a, T>(p: *mut T, n: usize, what: &str) -> Result<&'a mut [T], Fault> {
    if n == 0 {
        return Ok(&mut []);
    }
    if p.is_null() {
        return fault(format!("{what} is NULL with {n} elements"));
    }
    // SAFETY: non-null, n elements (caller's contract).
    Ok(unsafe { std::slice::from_raw_parts_mut(p, n) })
}

/// A C string (None for NULL; invalid UTF-8 replaced).
///
/// # Safety
/// A non-null `s` is NUL-terminated.
unsafe fn text(s: *const c_char) -> Option<String> {
    if s.is_null() {
        return None;
    }
    // SAFETY: non-null, NUL-terminated (caller's contract).
    Some(unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned())
}

/// Checks a get/set call's counts: every variable here is a scalar.
fn counts(n_vrs: usize, n_values: usize) -> Result<(), Fault> {
    if n_vrs == n_values {
        Ok(())
    } else {
        fault(format!(
            "nValues = {n_values} but nValueReferences = {n_vrs}: every variable of this FMU is a scalar"
        ))
    }
}

/// Reads the variables of `vrs` into `values` with `get`.
fn get_all<T>(
    inst: &mut Instance,
    vrs: &[u32],
    values: &mut [T],
    mut get: impl FnMut(&mut Model, &'static crate::variables::Variable) -> Result<T, Fault>,
) -> Outcome {
    for (vr, slot) in vrs.iter().zip(values.iter_mut()) {
        *slot = get(&mut inst.model, variable(*vr)?)?;
    }
    Ok(Status::Ok)
}

/// Sets the variables of `vrs` from `values` with `set`; the worst status.
fn set_all<T: Copy>(
    inst: &mut Instance,
    vrs: &[u32],
    values: &[T],
    mut set: impl FnMut(&mut Model, &'static crate::variables::Variable, T) -> Outcome,
) -> Outcome {
    let mut status = Status::Ok;
    for (vr, value) in vrs.iter().zip(values.iter()) {
        status = status.max(set(&mut inst.model, variable(*vr)?, *value)?);
    }
    Ok(status)
}

macro_rules! get_set {
    ($get:ident, $set:ident, $c:ty, $get_model:ident, $set_model:ident, $to_c:expr, $from_c:expr) => {
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $get(
            instance: *mut c_void,
            vrs: *const u32,
            n_vrs: usize,
            values: *mut $c,
            n_values: usize,
        ) -> c_int {
            call(instance, stringify!($get), |inst| {
                counts(n_vrs, n_values)?;
                // SAFETY: arrays of the given lengths (FMI contract).
                let vrs = unsafe { slice(vrs, n_vrs, "valueReferences") }?;
                let values = unsafe { slice_mut(values, n_values, "values") }?;
                get_all(inst, vrs, values, |m, v| m.$get_model(v).map($to_c))
            })
        }

        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $set(
            instance: *mut c_void,
            vrs: *const u32,
            n_vrs: usize,
            values: *const $c,
            n_values: usize,
        ) -> c_int {
            call(instance, stringify!($set), |inst| {
                counts(n_vrs, n_values)?;
                // SAFETY: arrays of the given lengths (FMI contract).
                let vrs = unsafe { slice(vrs, n_vrs, "valueReferences") }?;
                let values = unsafe { slice(values, n_values, "values") }?;
                set_all(inst, vrs, values, |m, v, x| m.$set_model(v, $from_c(x)))
            })
        }
    };
}

get_set!(
    fmi3GetFloat64,
    fmi3SetFloat64,
    f64,
    get_f64,
    set_f64,
    |x| x,
    |x| x
);
get_set!(
    fmi3GetUInt32,
    fmi3SetUInt32,
    u32,
    get_u32,
    set_u32,
    |x| x,
    |x| x
);
get_set!(
    fmi3GetInt64,
    fmi3SetInt64,
    i64,
    get_i64,
    set_i64,
    |x| x,
    |x| x
);
// fmi3Boolean is C's bool: read as a byte (any non-zero is true), so no value is invalid.
get_set!(
    fmi3GetBoolean,
    fmi3SetBoolean,
    u8,
    get_bool,
    set_bool,
    u8::from,
    |x: u8| x != 0
);

/// `fmi3GetString`: the strings stay valid until the next call on the instance.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3GetString(
    instance: *mut c_void,
    vrs: *const u32,
    n_vrs: usize,
    values: *mut *const c_char,
    n_values: usize,
) -> c_int {
    call(instance, "fmi3GetString", |inst| {
        counts(n_vrs, n_values)?;
        // SAFETY: arrays of the given lengths (FMI contract).
        let vrs = unsafe { slice(vrs, n_vrs, "valueReferences") }?;
        let values = unsafe { slice_mut(values, n_values, "values") }?;
        let mut strings = Vec::with_capacity(vrs.len());
        for vr in vrs {
            let s = inst.model.get_string(variable(*vr)?)?;
            strings.push(CString::new(s.replace('\0', " ")).unwrap_or_default());
        }
        for (slot, s) in values.iter_mut().zip(&strings) {
            *slot = s.as_ptr();
        }
        inst.strings = strings;
        Ok(Status::Ok)
    })
}

/// `fmi3SetString` (`params_file` loads a parameter file).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3SetString(
    instance: *mut c_void,
    vrs: *const u32,
    n_vrs: usize,
    values: *const *const c_char,
    n_values: usize,
) -> c_int {
    call(instance, "fmi3SetString", |inst| {
        counts(n_vrs, n_values)?;
        // SAFETY: arrays of the given lengths (FMI contract).
        let vrs = unsafe { slice(vrs, n_vrs, "valueReferences") }?;
        let values = unsafe { slice(values, n_values, "values") }?;
        for (vr, s) in vrs.iter().zip(values) {
            // SAFETY: NUL-terminated strings (FMI contract); NULL is refused.
            let s = unsafe { text(*s) }.map_or_else(|| fault("a string value is NULL"), Ok)?;
            let (_, note) = inst.model.set_string(variable(*vr)?, &s)?;
            if let Some(note) = note {
                inst.event(&note);
            }
        }
        Ok(Status::Ok)
    })
}

/// The get/set functions of types no variable of this FMU has.
macro_rules! no_such_type {
    ($($get:ident, $set:ident, $c:ty, $name:literal;)*) => {$(
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $get(
            instance: *mut c_void,
            _vrs: *const u32,
            n_vrs: usize,
            _values: *mut $c,
            _n_values: usize,
        ) -> c_int {
            call(instance, stringify!($get), |_| no_variables(n_vrs, $name))
        }

        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $set(
            instance: *mut c_void,
            _vrs: *const u32,
            n_vrs: usize,
            _values: *const $c,
            _n_values: usize,
        ) -> c_int {
            call(instance, stringify!($set), |_| no_variables(n_vrs, $name))
        }
    )*};
}

fn no_variables(n_vrs: usize, kind: &str) -> Outcome {
    if n_vrs == 0 {
        Ok(Status::Ok)
    } else {
        fault(format!(
            "this FMU has no {kind} variables (its types: Float64, UInt32, Boolean, String, Enumeration as Int64)"
        ))
    }
}

no_such_type!(
    fmi3GetFloat32, fmi3SetFloat32, f32, "Float32";
    fmi3GetInt8, fmi3SetInt8, i8, "Int8";
    fmi3GetUInt8, fmi3SetUInt8, u8, "UInt8";
    fmi3GetInt16, fmi3SetInt16, i16, "Int16";
    fmi3GetUInt16, fmi3SetUInt16, u16, "UInt16";
    fmi3GetInt32, fmi3SetInt32, i32, "Int32";
    fmi3GetUInt64, fmi3SetUInt64, u64, "UInt64";
);

/// `fmi3GetVersion`.
#[unsafe(no_mangle)]
pub extern "C" fn fmi3GetVersion() -> *const c_char {
    c"3.0".as_ptr()
}

/// `fmi3SetDebugLogging`: on or off for the named categories (none named: all).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3SetDebugLogging(
    instance: *mut c_void,
    logging_on: u8,
    n_categories: usize,
    categories: *const *const c_char,
) -> c_int {
    call(instance, "fmi3SetDebugLogging", |inst| {
        // SAFETY: an array of n_categories strings (FMI contract).
        let names = unsafe { slice(categories, n_categories, "categories") }?;
        let on = logging_on != 0;
        inst.logger.debug = on;
        if names.is_empty() {
            inst.logger.categories = [on; LOG_CATEGORIES.len()];
        }
        for name in names {
            // SAFETY: NUL-terminated (FMI contract).
            let name = unsafe { text(*name) }.unwrap_or_default();
            match LOG_CATEGORIES.iter().position(|(n, _)| *n == name) {
                Some(i) => inst.logger.categories[i] = on,
                None => {
                    let known: Vec<&str> = LOG_CATEGORIES.iter().map(|(n, _)| *n).collect();
                    return fault(format!(
                        "log category `{name}` is not one of this FMU's ({})",
                        known.join(", ")
                    ));
                }
            }
        }
        Ok(Status::Ok)
    })
}

/// The parameter file of the FMU's resources: its defaults.
fn resource_defaults(
    resource_path: Option<String>,
) -> Result<(hils_sil::ParamFile, String), String> {
    let Some(dir) = resource_path.filter(|p| !p.is_empty()) else {
        return Ok((
            hils_sil::ParamFile::default(),
            "no resource path given: the built-in defaults (equal to resources/parameters.toml) are used".into(),
        ));
    };
    let dir = dir.strip_prefix("file://").unwrap_or(&dir).to_string();
    let path = PathBuf::from(dir).join(crate::RESOURCE_FILE);
    if !path.exists() {
        return Ok((
            hils_sil::ParamFile::default(),
            format!(
                "{} not found: the built-in defaults (equal to it) are used",
                path.display()
            ),
        ));
    }
    crate::load_params(&path)
        .map(|f| (f, format!("defaults loaded from {}", path.display())))
        .map_err(|Fault(e)| e)
}

/// Why this binary cannot run on this CPU, if it cannot: a build for x86-64-v3 (the host
/// build of `.cargo/config.toml`) on a CPU without AVX2/FMA would stop at its first such
/// instruction; said instead (best effort, as `hils` does at its start).
fn cpu_unsupported() -> Option<&'static str> {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    if !(std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma"))
    {
        return Some(
            "this FMU's binary was built for x86-64-v3 (AVX2, FMA) but this CPU lacks them: rebuild it with RUSTFLAGS=\"-C target-cpu=x86-64\" cargo fmu (the same results, about 5 % slower)",
        );
    }
    None
}

/// `fmi3InstantiateCoSimulation`: NULL (with a logged message) for a wrong token, a bad
/// parameter resource or a CPU the binary was not built for.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3InstantiateCoSimulation(
    instance_name: *const c_char,
    instantiation_token: *const c_char,
    resource_path: *const c_char,
    _visible: u8,
    logging_on: u8,
    event_mode_used: u8,
    _early_return_allowed: u8,
    _required_intermediate_variables: *const u32,
    n_required_intermediate_variables: usize,
    instance_environment: *mut c_void,
    log_message: Option<LogMessage>,
    _intermediate_update: *const c_void,
) -> *mut c_void {
    let logger = Logger {
        callback: log_message,
        environment: instance_environment,
        debug: logging_on != 0,
        categories: [logging_on != 0; LOG_CATEGORIES.len()],
    };
    let result = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: NUL-terminated strings or NULL (FMI contract).
        let name = unsafe { text(instance_name) }.unwrap_or_else(|| "hils_plant".into());
        let token = unsafe { text(instantiation_token) }.unwrap_or_default();
        let refuse = |message: String| {
            logger.log(
                Status::Error,
                CATEGORY_ERROR,
                &format!("{name} (fmi3InstantiateCoSimulation): {message}"),
            );
            Err(())
        };
        if let Some(why) = cpu_unsupported() {
            return refuse(why.to_string());
        }
        let expected = crate::description::instantiation_token();
        if token != expected {
            return refuse(format!(
                "instantiationToken `{token}` is not this binary's `{expected}` (modelDescription.xml and binary from different builds)"
            ));
        }
        let (defaults, note) = match resource_defaults(unsafe { text(resource_path) }) {
            Ok(d) => d,
            Err(e) => return refuse(format!("the FMU's parameter resource is refused: {e}")),
        };
        let instance = Instance {
            magic: MAGIC,
            name,
            logger: Logger { ..logger },
            model: Model::new(defaults),
            strings: Vec::new(),
            broken: None,
        };
        instance.event(&note);
        if event_mode_used != 0 {
            instance.warning("eventModeUsed = true, but this FMU has no event mode (hasEventMode = false): it is not used");
        }
        if n_required_intermediate_variables > 0 {
            instance.warning("requiredIntermediateVariables given, but this FMU provides no intermediate update: ignored");
        }
        let pointer = Box::into_raw(Box::new(instance)) as *mut c_void;
        LIVE.lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .push(pointer as usize);
        Ok(pointer)
    }));
    match result {
        Ok(Ok(p)) => p,
        _ => std::ptr::null_mut(),
    }
}

/// `fmi3FreeInstance` (NULL, a pointer freed already or a foreign one: nothing).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3FreeInstance(instance: *mut c_void) {
    if !take_live(instance) {
        return;
    }
    // SAFETY: a live instance of ours (it was in LIVE).
    if let Some(inst) = unsafe { instance_of(instance) } {
        inst.magic = 0;
        // SAFETY: allocated by Box::into_raw in fmi3InstantiateCoSimulation, freed once
        // (the magic is cleared above).
        let _ = catch_unwind(AssertUnwindSafe(|| {
            drop(unsafe { Box::from_raw(instance as *mut Instance) })
        }));
    }
}

/// `fmi3EnterInitializationMode`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3EnterInitializationMode(
    instance: *mut c_void,
    _tolerance_defined: u8,
    _tolerance: f64,
    start_time: f64,
    stop_time_defined: u8,
    stop_time: f64,
) -> c_int {
    call(instance, "fmi3EnterInitializationMode", |inst| {
        let stop = (stop_time_defined != 0).then_some(stop_time);
        inst.model.enter_initialization_mode(start_time, stop)
    })
}

/// `fmi3ExitInitializationMode`: builds the model; refused parameters are logged.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3ExitInitializationMode(instance: *mut c_void) -> c_int {
    call(instance, "fmi3ExitInitializationMode", |inst| {
        let status = inst.model.exit_initialization_mode()?;
        inst.event("model built; Step Mode");
        Ok(status)
    })
}

/// `fmi3EnterStepMode` (Step Mode is entered from initialisation directly: no event mode).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3EnterStepMode(instance: *mut c_void) -> c_int {
    call(instance, "fmi3EnterStepMode", |inst| {
        if inst.model.mode() == crate::instance::Mode::Step {
            Ok(Status::Ok)
        } else {
            fault(format!(
                "not allowed in {}: this FMU has no event mode",
                inst.model.mode().name()
            ))
        }
    })
}

/// `fmi3Terminate`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3Terminate(instance: *mut c_void) -> c_int {
    call(instance, "fmi3Terminate", |inst| inst.model.terminate())
}

/// `fmi3Reset`: back to the instantiated state with the resource's defaults.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3Reset(instance: *mut c_void) -> c_int {
    call(instance, "fmi3Reset", |inst| {
        inst.model.reset();
        inst.broken = None;
        Ok(Status::Ok)
    })
}

/// `fmi3EnterConfigurationMode`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3EnterConfigurationMode(instance: *mut c_void) -> c_int {
    call(instance, "fmi3EnterConfigurationMode", |inst| {
        inst.model.enter_configuration_mode()
    })
}

/// `fmi3ExitConfigurationMode`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3ExitConfigurationMode(instance: *mut c_void) -> c_int {
    call(instance, "fmi3ExitConfigurationMode", |inst| {
        inst.model.exit_configuration_mode()
    })
}

/// `fmi3DoStep`: a whole number of plant steps (a communication step that is not a
/// multiple of the plant step is refused with a logged message).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3DoStep(
    instance: *mut c_void,
    current_communication_point: f64,
    communication_step_size: f64,
    _no_set_fmu_state_prior_to_current_point: u8,
    event_handling_needed: *mut u8,
    terminate_simulation: *mut u8,
    early_return: *mut u8,
    last_successful_time: *mut f64,
) -> c_int {
    call(instance, "fmi3DoStep", |inst| {
        let result = inst
            .model
            .do_step(current_communication_point, communication_step_size);
        // SAFETY: the out-arguments are NULL or valid (FMI contract).
        unsafe {
            for flag in [event_handling_needed, terminate_simulation, early_return] {
                if let Some(f) = flag.as_mut() {
                    *f = 0;
                }
            }
            if let Some(t) = last_successful_time.as_mut() {
                *t = inst.model.time_s();
            }
        }
        let (status, warning) = result?;
        if let Some(w) = warning {
            inst.warning(&w);
        }
        Ok(status)
    })
}

/// A saved FMU state (`fmi3GetFMUState`).
struct SavedState {
    magic: u64,
    model: Model,
}

/// `fmi3GetFMUState`: a copy of the whole instance state (reuses `*state` when given).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3GetFMUState(instance: *mut c_void, state: *mut *mut c_void) -> c_int {
    call(instance, "fmi3GetFMUState", |inst| {
        // SAFETY: `state` is NULL or points to a state pointer (FMI contract).
        let Some(slot) = (unsafe { state.as_mut() }) else {
            return fault("FMUState is NULL");
        };
        // SAFETY: a non-null *slot is a state of ours (checked by its magic).
        match unsafe { (*slot as *mut SavedState).as_mut() } {
            Some(saved) if saved.magic == STATE_MAGIC => saved.model = inst.model.clone(),
            Some(_) => return fault("*FMUState is not a state of this FMU"),
            None => {
                let saved = Box::new(SavedState {
                    magic: STATE_MAGIC,
                    model: inst.model.clone(),
                });
                *slot = Box::into_raw(saved) as *mut c_void;
            }
        }
        Ok(Status::Ok)
    })
}

/// `fmi3SetFMUState`: restores a saved state.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3SetFMUState(instance: *mut c_void, state: *mut c_void) -> c_int {
    call(instance, "fmi3SetFMUState", |inst| {
        // SAFETY: a state pointer from fmi3GetFMUState (checked by its magic).
        match unsafe { (state as *mut SavedState).as_ref() } {
            Some(saved) if saved.magic == STATE_MAGIC => {
                inst.model = saved.model.clone();
                Ok(Status::Ok)
            }
            _ => fault("FMUState is NULL or not a state of this FMU"),
        }
    })
}

/// `fmi3FreeFMUState`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3FreeFMUState(instance: *mut c_void, state: *mut *mut c_void) -> c_int {
    call(instance, "fmi3FreeFMUState", |_| {
        // SAFETY: `state` is NULL or points to a state pointer (FMI contract).
        let Some(slot) = (unsafe { state.as_mut() }) else {
            return Ok(Status::Ok);
        };
        let p = *slot as *mut SavedState;
        // SAFETY: a non-null state of ours (magic), allocated by Box::into_raw.
        match unsafe { p.as_mut() } {
            None => Ok(Status::Ok),
            Some(saved) if saved.magic == STATE_MAGIC => {
                saved.magic = 0;
                drop(unsafe { Box::from_raw(p) });
                *slot = std::ptr::null_mut();
                Ok(Status::Ok)
            }
            Some(_) => fault("*FMUState is not a state of this FMU"),
        }
    })
}

/// Functions of interfaces or capabilities this FMU does not have: refused, logged.
macro_rules! unsupported {
    ($($name:ident($($arg:ident: $ty:ty),*);)*) => {$(
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn $name(instance: *mut c_void, $($arg: $ty),*) -> c_int {
            $(let _ = $arg;)*
            call(instance, stringify!($name), |_| fault(
                "not supported: hils_plant is a Co-Simulation FMU without event mode, clocks, derivatives or state serialisation"
            ))
        }
    )*};
}

unsupported!(
    fmi3EnterEventMode();
    fmi3GetBinary(a: *const u32, b: usize, c: *mut usize, d: *mut *const u8, e: usize);
    fmi3SetBinary(a: *const u32, b: usize, c: *const usize, d: *const *const u8, e: usize);
    fmi3GetClock(a: *const u32, b: usize, c: *mut u8);
    fmi3SetClock(a: *const u32, b: usize, c: *const u8);
    fmi3GetNumberOfVariableDependencies(a: u32, b: *mut usize);
    fmi3GetVariableDependencies(a: u32, b: *mut usize, c: *mut u32, d: *mut usize, e: *mut c_int, f: usize);
    fmi3SerializedFMUStateSize(a: *mut c_void, b: *mut usize);
    fmi3SerializeFMUState(a: *mut c_void, b: *mut u8, c: usize);
    fmi3DeserializeFMUState(a: *const u8, b: usize, c: *mut *mut c_void);
    fmi3GetDirectionalDerivative(a: *const u32, b: usize, c: *const u32, d: usize, e: *const f64, f: usize, g: *mut f64, h: usize);
    fmi3GetAdjointDerivative(a: *const u32, b: usize, c: *const u32, d: usize, e: *const f64, f: usize, g: *mut f64, h: usize);
    fmi3GetIntervalDecimal(a: *const u32, b: usize, c: *mut f64, d: *mut c_int);
    fmi3GetIntervalFraction(a: *const u32, b: usize, c: *mut u64, d: *mut u64, e: *mut c_int);
    fmi3GetShiftDecimal(a: *const u32, b: usize, c: *mut f64);
    fmi3GetShiftFraction(a: *const u32, b: usize, c: *mut u64, d: *mut u64);
    fmi3SetIntervalDecimal(a: *const u32, b: usize, c: *const f64);
    fmi3SetIntervalFraction(a: *const u32, b: usize, c: *const u64, d: *const u64);
    fmi3SetShiftDecimal(a: *const u32, b: usize, c: *const f64);
    fmi3SetShiftFraction(a: *const u32, b: usize, c: *const u64, d: *const u64);
    fmi3EvaluateDiscreteStates();
    fmi3UpdateDiscreteStates(a: *mut u8, b: *mut u8, c: *mut u8, d: *mut u8, e: *mut u8, f: *mut f64);
    fmi3EnterContinuousTimeMode();
    fmi3CompletedIntegratorStep(a: u8, b: *mut u8, c: *mut u8);
    fmi3SetTime(a: f64);
    fmi3SetContinuousStates(a: *const f64, b: usize);
    fmi3GetContinuousStateDerivatives(a: *mut f64, b: usize);
    fmi3GetEventIndicators(a: *mut f64, b: usize);
    fmi3GetContinuousStates(a: *mut f64, b: usize);
    fmi3GetNominalsOfContinuousStates(a: *mut f64, b: usize);
    fmi3GetNumberOfEventIndicators(a: *mut usize);
    fmi3GetNumberOfContinuousStates(a: *mut usize);
    fmi3GetOutputDerivatives(a: *const u32, b: usize, c: *const i32, d: *mut f64, e: usize);
    fmi3ActivateModelPartition(a: u32, b: f64);
);

/// `fmi3InstantiateModelExchange`: NULL (Co-Simulation only), logged.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3InstantiateModelExchange(
    _instance_name: *const c_char,
    _instantiation_token: *const c_char,
    _resource_path: *const c_char,
    _visible: u8,
    _logging_on: u8,
    instance_environment: *mut c_void,
    log_message: Option<LogMessage>,
) -> *mut c_void {
    refuse_interface(instance_environment, log_message, "Model Exchange")
}

/// `fmi3InstantiateScheduledExecution`: NULL (Co-Simulation only), logged.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3InstantiateScheduledExecution(
    _instance_name: *const c_char,
    _instantiation_token: *const c_char,
    _resource_path: *const c_char,
    _visible: u8,
    _logging_on: u8,
    instance_environment: *mut c_void,
    log_message: Option<LogMessage>,
    _clock_update: *const c_void,
    _lock_preemption: *const c_void,
    _unlock_preemption: *const c_void,
) -> *mut c_void {
    refuse_interface(instance_environment, log_message, "Scheduled Execution")
}

fn refuse_interface(
    environment: *mut c_void,
    callback: Option<LogMessage>,
    interface: &str,
) -> *mut c_void {
    let logger = Logger {
        callback,
        environment,
        debug: false,
        categories: [false; LOG_CATEGORIES.len()],
    };
    let _ = catch_unwind(AssertUnwindSafe(|| {
        logger.log(
            Status::Error,
            CATEGORY_ERROR,
            &format!("hils_plant: {interface} is not supported (a Co-Simulation FMU)"),
        )
    }));
    std::ptr::null_mut()
}
