//! Native HDF5 records, readable by h5py without tacit.
//!
//! Layout:
//! - root attributes `format = "tacit-record"` (string), `version = 1`,
//!   `fs` (Hz, f64), `t0` (s, f64);
//! - dataset `/time` (f64, N): `t0 + k/fs`;
//! - groups `/inputs` and `/outputs`: one 1-D f64 dataset per channel, named
//!   `<quantity>_<dof>` (`force_1`, `accel_5`), with attributes `quantity`
//!   (string), `dof` (integer, from 1) and `unit` (string);
//! - optional group `/truth`: 2-D f64 datasets `u`, `v`, `fint` and (when
//!   present) `a`, shape (ndof, N), row = DOF; attribute `model_toml`.
//!
//! Channels are read back in the order they were written (links are created
//! with creation order tracked); files without that index (e.g. from h5py)
//! give channels sorted by quantity and DOF. On read, missing `quantity` /
//! `dof` / `unit` attributes are inferred from the name (unit: SI); `fs` and
//! `t0` may be missing when `/time` is present, and `/time` may be missing
//! when `fs` is present (`t0` then defaults to 0).

use super::csvio::{
    check_channel_lengths, check_finite, check_truth, parse_channel_name, time_base, Msg, TIME_RTOL,
};
use super::{Channel, Quantity, Record, Truth};
use crate::error::{Result, TacitError};
use hdf5::plist::group_create::LinkCreationOrder;
use hdf5::types::{TypeDescriptor, VarLenAscii, VarLenUnicode};
use hdf5::{Dataset, Group, H5Type, IndexType, IterationOrder, Location};
use ndarray::Array2;
use std::path::Path;
use std::str::FromStr;

/// Value of the root `format` attribute.
const FORMAT: &str = "tacit-record";
/// Layout version written and understood.
const VERSION: i64 = 1;

/// HDF5 file locking off for tacit's own processes (unless the user set
/// `HDF5_USE_FILE_LOCKING`): records are written to a temporary file and
/// renamed, so a lock adds nothing, and a lock still held by a writer that
/// has not fully released the file (seen with a parent process handing a
/// fresh record to a child) would make a read fail with EAGAIN.
pub(crate) fn no_file_locking() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("HDF5_USE_FILE_LOCKING").is_none() {
            std::env::set_var("HDF5_USE_FILE_LOCKING", "FALSE");
        }
    });
}

/// Read an HDF5 record. Errors name the file, the channel and the sample.
pub fn read(path: &Path) -> Result<Record> {
    no_file_locking();
    let meta = std::fs::metadata(path).map_err(|e| TacitError::io(path, e))?;
    if meta.len() == 0 {
        return Err(TacitError::record(path, "the file is empty"));
    }
    let mut rec = read_file(path).map_err(|m| TacitError::record(path, m))?;
    rec.source = path.to_path_buf();
    Ok(rec)
}

/// Write a record to exactly `path` (the caller handles atomicity).
pub fn write(rec: &Record, path: &Path) -> Result<()> {
    no_file_locking();
    write_file(rec, path).map_err(|m| TacitError::record(path, m))
}

/// Wrap an HDF5 error with what was being done.
fn h5(what: impl std::fmt::Display) -> impl Fn(hdf5::Error) -> String {
    move |e| format!("{what}: HDF5: {e}")
}

fn write_file(rec: &Record, path: &Path) -> Msg<()> {
    check_channel_lengths(rec)?;
    if let Some(t) = &rec.truth {
        check_truth(t, rec.len())?;
    }
    let file = hdf5::File::create(path).map_err(h5("cannot create the file"))?;
    put_str(&file, "format", FORMAT)?;
    put_scalar(&file, "version", &VERSION)?;
    put_scalar(&file, "fs", &rec.fs)?;
    put_scalar(&file, "t0", &rec.t0)?;
    file.new_dataset_builder()
        .with_data(rec.times().as_slice())
        .create("time")
        .map_err(h5("cannot write /time"))?;
    write_channels(&file, "inputs", &rec.inputs)?;
    write_channels(&file, "outputs", &rec.outputs)?;
    if let Some(t) = &rec.truth {
        write_truth(&file, t)?;
    }
    file.close().map_err(h5("cannot close the file"))
}

/// A group whose links remember their creation order.
fn ordered_group(parent: &Group, name: &str) -> Msg<Group> {
    parent
        .create_group_builder()
        .with_create_plist(|p| p.link_creation_order(LinkCreationOrder::Indexed))
        .create(name)
        .map_err(h5(format!("cannot create group /{name}")))
}

fn write_channels(file: &Group, gname: &str, chans: &[Channel]) -> Msg<()> {
    let g = ordered_group(file, gname)?;
    for c in chans {
        let name = c.name();
        let what = format!("cannot write /{gname}/{name}");
        let ds = g
            .new_dataset_builder()
            .with_data(c.data.as_slice())
            .create(name.as_str())
            .map_err(h5(&what))?;
        put_str(&ds, "quantity", c.quantity.prefix())?;
        put_scalar(&ds, "dof", &(c.dof as u64))?;
        put_str(&ds, "unit", &c.unit)?;
    }
    Ok(())
}

fn write_truth(file: &Group, t: &Truth) -> Msg<()> {
    let g = ordered_group(file, "truth")?;
    for (name, m) in [("u", &t.u), ("v", &t.v), ("a", &t.a), ("fint", &t.fint)] {
        if m.is_empty() {
            continue; // no accelerations in this truth
        }
        let n = m[0].len();
        let flat: Vec<f64> = m.iter().flatten().copied().collect();
        let arr =
            Array2::from_shape_vec((m.len(), n), flat).map_err(|e| format!("truth {name}: {e}"))?;
        g.new_dataset_builder()
            .with_data(&arr)
            .create(name)
            .map_err(h5(format!("cannot write /truth/{name}")))?;
    }
    put_str(&g, "model_toml", &t.model_toml)
}

fn put_str(loc: &Location, name: &str, value: &str) -> Msg<()> {
    let v = VarLenUnicode::from_str(value)
        .map_err(|e| format!("attribute {name}: not storable as an HDF5 string ({e})"))?;
    put_scalar(loc, name, &v)
}

fn put_scalar<T: H5Type>(loc: &Location, name: &str, value: &T) -> Msg<()> {
    let what = format!("cannot write attribute {name}");
    loc.new_attr::<T>()
        .shape(())
        .create(name)
        .and_then(|a| a.write_scalar(value))
        .map_err(h5(what))
}

fn read_file(path: &Path) -> Msg<Record> {
    let file = hdf5::File::open(path).map_err(h5("cannot open as HDF5"))?;
    if let Some(f) = get_str(&file, "format")? {
        if f != FORMAT {
            return Err(format!(
                "attribute format is \"{f}\", expected \"{FORMAT}\""
            ));
        }
    }
    if let Some(v) = get_f64(&file, "version")? {
        if v != VERSION as f64 {
            return Err(format!(
                "layout version {v} is not supported (this tacit reads version {VERSION})"
            ));
        }
    }
    let (t0, fs, time_len) = read_time_base(&file)?;
    let inputs = read_channels(&file, "inputs")?;
    let outputs = read_channels(&file, "outputs")?;
    let n = check_lengths(&inputs, &outputs, time_len)?;
    let truth = read_truth(&file, n)?;
    Ok(Record {
        t0,
        fs,
        inputs,
        outputs,
        truth,
        source: path.to_path_buf(),
    })
}

/// `(t0, fs, length of /time if present)` from the attributes and `/time`,
/// checked against each other.
fn read_time_base(file: &Group) -> Msg<(f64, f64, Option<usize>)> {
    let fs_attr = get_f64(file, "fs")?;
    let t0_attr = get_f64(file, "t0")?;
    if let Some(fs) = fs_attr {
        if !(fs.is_finite() && fs > 0.0) {
            return Err(format!("attribute fs = {fs} Hz is not positive"));
        }
    }
    if let Some(t0) = t0_attr.filter(|t| !t.is_finite()) {
        return Err(format!("attribute t0 = {t0} s is not finite"));
    }
    if !file.link_exists("time") {
        let fs = fs_attr.ok_or("neither an fs attribute nor a /time dataset: no sample rate")?;
        return Ok((t0_attr.unwrap_or(0.0), fs, None));
    }
    let ds = file.dataset("time").map_err(h5("/time is not a dataset"))?;
    let t = read_vector(&ds, "time")?;
    let (tt0, tfs) = time_base(&t)?;
    let fs = fs_attr.unwrap_or(tfs);
    if (tfs - fs).abs() > TIME_RTOL * fs {
        return Err(format!(
            "attribute fs = {fs} Hz but /time has a mean step of {} s ({tfs} Hz)",
            1.0 / tfs
        ));
    }
    let t0 = t0_attr.unwrap_or(tt0);
    if (tt0 - t0).abs() > TIME_RTOL / fs + 1e-10 * t0.abs() {
        return Err(format!("attribute t0 = {t0} s but /time starts at {tt0} s"));
    }
    Ok((t0, fs, Some(t.len())))
}

/// All channels share one length, equal to that of `/time` when present.
fn check_lengths(inputs: &[Channel], outputs: &[Channel], time_len: Option<usize>) -> Msg<usize> {
    let mut all = inputs.iter().chain(outputs);
    let first = all
        .next()
        .ok_or("no channel: /inputs and /outputs are both empty")?;
    let (n, what) = match time_len {
        Some(n) => (n, "/time".to_string()),
        None => (first.data.len(), format!("channel {}", first.name())),
    };
    for c in inputs.iter().chain(outputs) {
        if c.data.len() != n {
            return Err(format!(
                "channel {} has {} samples but {what} has {n}",
                c.name(),
                c.data.len()
            ));
        }
    }
    Ok(n)
}

/// Read every channel of `/inputs` or `/outputs`.
fn read_channels(file: &Group, gname: &str) -> Msg<Vec<Channel>> {
    if !file.link_exists(gname) {
        return Err(format!(
            "group /{gname} is missing (a record holds /inputs and /outputs, either may be empty)"
        ));
    }
    let g = file
        .group(gname)
        .map_err(h5(format!("/{gname} is not a group")))?;
    let (names, sort) =
        match g.member_names_by(IndexType::CreationOrder, IterationOrder::Increasing) {
            Ok(names) => (names, false),
            Err(_) => (
                g.member_names()
                    .map_err(h5(format!("cannot list /{gname}")))?,
                true,
            ),
        };
    let mut chans = names
        .iter()
        .map(|name| read_channel(&g, gname, name))
        .collect::<Msg<Vec<Channel>>>()?;
    if sort {
        chans.sort_by_key(|c| (c.quantity, c.dof));
    }
    Ok(chans)
}

fn read_channel(g: &Group, gname: &str, name: &str) -> Msg<Channel> {
    let point = super::parse_point_name(name);
    let (q, dof) = match point {
        Some((q, _)) => (q, 0),
        None => parse_channel_name(name).map_err(|m| format!("/{gname}: {m}"))?,
    };
    let label = format!("channel {name}");
    let ds = g
        .dataset(name)
        .map_err(h5(format!("/{gname}/{name} is not a dataset")))?;
    if let Some(qs) = get_str(&ds, "quantity")? {
        if Quantity::from_prefix(&qs) != Some(q) {
            return Err(format!(
                "{label}: attribute quantity is \"{qs}\" but the name says \"{}\"",
                q.prefix()
            ));
        }
    }
    // a labelled channel's `dof` attribute is the writer's numbering; the
    // label is resolved against the model instead
    if let (Some(d), None) = (get_f64(&ds, "dof")?, point) {
        if d != dof as f64 {
            return Err(format!(
                "{label}: attribute dof is {d} but the name says {dof}"
            ));
        }
    }
    match (gname, q) {
        ("inputs", q) if q != Quantity::Force => {
            return Err(format!("{label} in /inputs is not a force"))
        }
        ("outputs", Quantity::Force) => return Err(format!("{label} in /outputs is a force")),
        _ => {}
    }
    let unit = get_str(&ds, "unit")?.unwrap_or_else(|| q.si_unit().to_string());
    let data = read_vector(&ds, &label)?;
    check_finite(&data, &label)?;
    Ok(Channel {
        quantity: q,
        dof,
        point: point.map(|(_, p)| p.to_string()),
        unit,
        data,
    })
}

/// Deflate, the strongest of HDF5's standard filters, stores at most
/// about 1032 values' bytes in one byte (RFC 1951: a 258-byte match in a
/// code of about 2 bits).
const MAX_DEFLATE_RATIO: u64 = 1032;

/// Refuse a dataset that declares more values than its file can hold:
/// unfiltered, its values are stored in the file; through a filter, at
/// most [`MAX_DEFLATE_RATIO`] times the file. A larger declared size is a
/// corrupt header, not data (a fuzzed header of the 1.4 MB shipped record
/// asked for 2.5 GB). Then refuse a read larger than the memory the
/// machine has available.
fn check_declared_size(ds: &Dataset, label: &str) -> Msg<()> {
    let file_len = ds.file().map(|f| f.size()).unwrap_or(0);
    let item = ds.dtype().map_or(8, |t| t.size()) as u64;
    let needed = (ds.size() as u64).saturating_mul(item);
    let filtered = !ds.filters().is_empty();
    let ratio = if filtered { MAX_DEFLATE_RATIO } else { 1 };
    let limit = file_len.saturating_mul(ratio).max(1 << 20);
    if needed > limit {
        let how = if filtered {
            format!(", {MAX_DEFLATE_RATIO} times what deflate stores in one byte")
        } else {
            String::new()
        };
        return Err(format!(
            "{label}: declares {} values (shape {:?}, {needed} bytes stored), more than a file of {file_len} bytes can hold{how}; the file is corrupt or truncated",
            ds.size(),
            ds.shape()
        ));
    }
    // the values as stored, and as f64
    let bytes = needed.saturating_add((ds.size() as u64).saturating_mul(8));
    fits_in_memory(bytes, crate::io::available_memory(), label)
}

/// Refuse reading `bytes` when more than `available` (`None`: unknown).
fn fits_in_memory(bytes: u64, available: Option<u64>, label: &str) -> Msg<()> {
    match available {
        Some(avail) if bytes > avail => Err(format!(
            "{label}: reading it needs about {:.1} GB of memory; the machine has {:.1} GB available",
            bytes as f64 / 1e9,
            avail as f64 / 1e9
        )),
        _ => Ok(()),
    }
}

/// Refuse an attribute whose declared size no file of this size holds:
/// more bytes of values than the file, or a variable-length string of
/// characters wider than 4 bytes (HDF5 strings hold 1-byte characters;
/// libhdf5 allocates length × width bytes to convert one: a fuzzed width
/// of 1.7 GB in the shipped record's `unit` attribute asked for 8.7 GB).
fn check_attr(attr: &hdf5::Attribute, name: &str) -> Msg<()> {
    let file_len = attr.file().map(|f| f.size()).unwrap_or(0);
    let dtype = attr
        .dtype()
        .map_err(h5(format!("attribute {name}: cannot read its type")))?;
    let needed = (attr.size() as u64).saturating_mul(dtype.size() as u64);
    if needed > file_len.max(1 << 16) {
        return Err(format!(
            "attribute {name}: declares {} values ({needed} bytes), more than a file of {file_len} bytes can hold; the file is corrupt",
            attr.size()
        ));
    }
    match vlen_char_width(&dtype) {
        Some(w) if w > 4 => Err(format!(
            "attribute {name}: a variable-length string of {w}-byte characters (HDF5 strings hold 1-byte characters); the file is corrupt"
        )),
        _ => Ok(()),
    }
}

/// Width in bytes of the characters of a variable-length string type (the
/// size of its base type); `None` for any other type. The safe API does
/// not expose the base type of a string.
fn vlen_char_width(t: &hdf5::Datatype) -> Option<usize> {
    use hdf5_sys::h5t::{H5Tclose, H5Tget_size, H5Tget_super, H5Tis_variable_str};
    hdf5::sync::sync(|| {
        // SAFETY: `t` keeps its datatype id open for the whole call, the
        // library lock is held, and the id H5Tget_super opens is closed
        // before returning.
        unsafe {
            if H5Tis_variable_str(t.id()) <= 0 {
                return None;
            }
            let base = H5Tget_super(t.id());
            if base < 0 {
                return None;
            }
            let width = H5Tget_size(base);
            H5Tclose(base);
            Some(width)
        }
    })
}

/// A dataset with at most one dimension larger than 1, as f64.
fn read_vector(ds: &Dataset, label: &str) -> Msg<Vec<f64>> {
    check_declared_size(ds, label)?;
    let shape = ds.shape();
    if shape.iter().filter(|d| **d > 1).count() > 1 {
        return Err(format!("{label}: shape {shape:?} is not a vector"));
    }
    ds.read_raw::<f64>()
        .map_err(h5(format!("{label}: cannot read as numbers")))
}

fn read_truth(file: &Group, n: usize) -> Msg<Option<Truth>> {
    if !file.link_exists("truth") {
        return Ok(None);
    }
    let g = file.group("truth").map_err(h5("/truth is not a group"))?;
    let a = if g.link_exists("a") {
        read_matrix(&g, "a", n)?
    } else {
        Vec::new()
    };
    let t = Truth {
        u: read_matrix(&g, "u", n)?,
        v: read_matrix(&g, "v", n)?,
        a,
        fint: read_matrix(&g, "fint", n)?,
        model_toml: get_str(&g, "model_toml")?.unwrap_or_default(),
    };
    check_truth(&t, n)?;
    Ok(Some(t))
}

/// A 2-D dataset of shape (ndof, n), one row per DOF.
fn read_matrix(g: &Group, name: &str, n: usize) -> Msg<Vec<Vec<f64>>> {
    if !g.link_exists(name) {
        return Err(format!("dataset /truth/{name} is missing"));
    }
    let ds = g
        .dataset(name)
        .map_err(h5(format!("/truth/{name} is not a dataset")))?;
    let shape = ds.shape();
    if shape.len() != 2 || shape[1] != n {
        return Err(format!(
            "/truth/{name} has shape {shape:?}, expected (ndof, {n})"
        ));
    }
    check_declared_size(&ds, &format!("/truth/{name}"))?;
    let arr = ds
        .read_2d::<f64>()
        .map_err(h5(format!("/truth/{name}: cannot read as numbers")))?;
    Ok(arr.outer_iter().map(|r| r.to_vec()).collect())
}

/// An attribute, or `None` when absent; refused when its declared size
/// cannot be real ([`check_attr`]).
fn get_attr(loc: &Location, name: &str) -> Msg<Option<hdf5::Attribute>> {
    let names = loc.attr_names().map_err(h5("cannot list attributes"))?;
    if !names.iter().any(|n| n == name) {
        return Ok(None);
    }
    let attr = loc
        .attr(name)
        .map_err(h5(format!("cannot open attribute {name}")))?;
    check_attr(&attr, name)?;
    Ok(Some(attr))
}

/// A one-element attribute of type `T`.
fn read_one<T: H5Type>(attr: &hdf5::Attribute, name: &str) -> Msg<T> {
    let mut v = attr
        .read_raw::<T>()
        .map_err(h5(format!("cannot read attribute {name}")))?;
    if v.len() != 1 {
        return Err(format!(
            "attribute {name} holds {} values, expected 1",
            v.len()
        ));
    }
    Ok(v.remove(0))
}

/// A string attribute (variable or fixed length, ASCII or UTF-8).
fn get_str(loc: &Location, name: &str) -> Msg<Option<String>> {
    let Some(attr) = get_attr(loc, name)? else {
        return Ok(None);
    };
    let desc = attr
        .dtype()
        .and_then(|t| t.to_descriptor())
        .map_err(h5(format!("attribute {name}")))?;
    let s = match desc {
        TypeDescriptor::VarLenUnicode => read_one::<VarLenUnicode>(&attr, name)?.to_string(),
        TypeDescriptor::VarLenAscii => read_one::<VarLenAscii>(&attr, name)?.to_string(),
        TypeDescriptor::FixedAscii(n) | TypeDescriptor::FixedUnicode(n) => {
            read_fixed_str(&attr, name, n)?
        }
        other => return Err(format!("attribute {name} is not a string ({other})")),
    };
    Ok(Some(s.trim_end_matches(['\0', ' ']).to_string()))
}

/// A fixed-length string attribute of `len` bytes, read in its own type
/// (a conversion to a shorter fixed type would cut it short without a
/// word): UTF-8, or an error naming the attribute.
fn read_fixed_str(attr: &hdf5::Attribute, name: &str, len: usize) -> Msg<String> {
    if attr.size() != 1 {
        return Err(format!(
            "attribute {name} holds {} values, expected 1",
            attr.size()
        ));
    }
    let dtype = attr
        .dtype()
        .map_err(h5(format!("attribute {name}: cannot read its type")))?;
    let mut buf = vec![0u8; len.max(dtype.size())];
    let status = hdf5::sync::sync(|| {
        // SAFETY: the attribute holds one value of `dtype`, whose size the
        // buffer covers; the ids stay open for the call; the lock is held.
        unsafe {
            hdf5_sys::h5a::H5Aread(
                attr.id(),
                dtype.id(),
                buf.as_mut_ptr().cast::<std::ffi::c_void>(),
            )
        }
    });
    if status < 0 {
        return Err(format!("cannot read attribute {name}"));
    }
    String::from_utf8(buf).map_err(|e| {
        format!(
            "attribute {name}: a string of {len} bytes that is not UTF-8 (byte {})",
            e.utf8_error().valid_up_to()
        )
    })
}

/// A numeric attribute as f64.
fn get_f64(loc: &Location, name: &str) -> Msg<Option<f64>> {
    match get_attr(loc, name)? {
        Some(attr) => read_one::<f64>(&attr, name).map(Some),
        None => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hdf5::types::FixedAscii;

    fn record_with_truth() -> Record {
        let n = 64;
        let sig =
            |s: f64, w: f64| -> Vec<f64> { (0..n).map(|k| s * (w * k as f64).sin()).collect() };
        let truth = Truth {
            u: vec![sig(1e-6, 0.1), sig(2e-6, 0.2), sig(3e-6, 0.3)],
            v: vec![sig(1e-3, 0.1), sig(2e-3, 0.2), sig(3e-3, 0.3)],
            a: vec![sig(1.0, 0.1), sig(2.0, 0.2), sig(3.0, 0.3)],
            fint: vec![sig(0.0, 0.0), sig(5.0, 0.7), sig(-5.0, 0.7)],
            model_toml: "[model]\nname = \"sdof ü\"\nk = [1.0, 2.0]\n".into(),
        };
        Record {
            t0: 0.125,
            fs: 610.3515625,
            inputs: vec![Channel::new(Quantity::Force, 2, sig(7.0, 0.37))],
            outputs: vec![
                Channel::new(Quantity::Disp, 3, sig(1e-5, 0.9)),
                Channel::new(Quantity::Accel, 10, sig(2.0, 0.5)),
                Channel::new(Quantity::Accel, 2, sig(3.0, 0.45)),
                Channel {
                    unit: "g".into(),
                    ..Channel::new(Quantity::Vel, 1, sig(0.5, 0.05))
                },
            ],
            truth: Some(truth),
            source: Default::default(),
        }
    }

    #[test]
    fn round_trip_is_exact_with_truth() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rec.h5");
        let rec = record_with_truth();
        write(&rec, &p).unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back.source, p);
        let mut want = rec.clone();
        want.source = p.clone();
        assert_eq!(back, want);
    }

    #[test]
    fn round_trip_without_truth_and_accel_truth() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rec.h5");
        let mut rec = record_with_truth();
        rec.truth = None;
        write(&rec, &p).unwrap();
        assert_eq!(read(&p).unwrap().truth, None);

        let mut rec = record_with_truth();
        rec.truth.as_mut().unwrap().a.clear();
        let q = dir.path().join("rec2.h5");
        write(&rec, &q).unwrap();
        assert_eq!(read(&q).unwrap().truth, rec.truth);
    }

    #[test]
    fn layout_is_as_documented() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rec.h5");
        let rec = record_with_truth();
        write(&rec, &p).unwrap();
        let f = hdf5::File::open(&p).unwrap();
        assert_eq!(get_str(&f, "format").unwrap().unwrap(), "tacit-record");
        assert_eq!(get_f64(&f, "version").unwrap(), Some(1.0));
        assert_eq!(get_f64(&f, "fs").unwrap(), Some(610.3515625));
        let t: Vec<f64> = f.dataset("time").unwrap().read_raw().unwrap();
        assert_eq!(t, rec.times());
        let ds = f.dataset("outputs/accel_10").unwrap();
        assert_eq!(get_str(&ds, "quantity").unwrap().unwrap(), "accel");
        assert_eq!(get_f64(&ds, "dof").unwrap(), Some(10.0));
        assert_eq!(get_str(&ds, "unit").unwrap().unwrap(), "m/s^2");
        let u = f.dataset("truth/u").unwrap();
        assert_eq!(u.shape(), vec![3, 64]);
        let u = u.read_2d::<f64>().unwrap();
        assert_eq!(u[[1, 5]], rec.truth.as_ref().unwrap().u[1][5]);
    }

    /// A file as h5py would write it: no creation order, no channel
    /// attributes, no fs/t0 attributes (rate from /time).
    #[test]
    fn minimal_foreign_file_is_read() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("min.h5");
        {
            let f = hdf5::File::create(&p).unwrap();
            let t: Vec<f64> = (0..10).map(|k| 2.0 + k as f64 / 100.0).collect();
            f.new_dataset_builder()
                .with_data(t.as_slice())
                .create("time")
                .unwrap();
            let g = f.create_group("inputs").unwrap();
            g.new_dataset_builder()
                .with_data(&[1.0f64; 10][..])
                .create("force_1")
                .unwrap();
            let g = f.create_group("outputs").unwrap();
            for name in ["disp_2", "accel_3", "accel_1"] {
                g.new_dataset_builder()
                    .with_data(&[2i32; 10][..])
                    .create(name)
                    .unwrap();
            }
            // numpy bytes attributes are fixed-length ASCII.
            let ds = g.dataset("disp_2").unwrap();
            let unit = FixedAscii::<8>::from_ascii(b"mm").unwrap();
            put_scalar(&ds, "unit", &unit).unwrap();
            let q = FixedAscii::<5>::from_ascii(b"disp").unwrap();
            put_scalar(&ds, "quantity", &q).unwrap();
        }
        let rec = read(&p).unwrap();
        assert!((rec.fs - 100.0).abs() < 1e-9);
        assert_eq!(rec.t0, 2.0);
        let names: Vec<String> = rec.outputs.iter().map(|c| c.name()).collect();
        assert_eq!(names, ["disp_2", "accel_1", "accel_3"]);
        assert_eq!(rec.outputs[1].data, vec![2.0; 10]);
        assert_eq!(rec.outputs[1].unit, "m/s^2");
        assert_eq!(rec.outputs[0].unit, "mm");
    }

    /// Strings of unusual length: a fixed-length `model_toml` of 3 000
    /// bytes (h5py writes numpy bytes as fixed-length strings; it was cut
    /// to 1 024 by the conversion), a variable-length one of 200 000
    /// characters, and an empty one, are read whole; a `unit` of 100 000
    /// characters is an error naming the channel, with the unit cut short.
    #[test]
    fn strings_of_unusual_length_are_read_whole_or_refused_by_name() {
        use hdf5::types::VarLenAscii;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.h5");
        write(&record_with_truth(), &p).unwrap();
        let line = "# a comment line of a long model file, 49 bytes.\n";
        let fixed: String = line.repeat(3000 / line.len());
        let long: String = "x".repeat(200_000);
        for (k, text) in [fixed.as_str(), long.as_str(), ""].iter().enumerate() {
            {
                let f = hdf5::File::open_rw(&p).unwrap();
                let g = f.group("truth").unwrap();
                g.delete_attr("model_toml").unwrap();
                if k == 0 {
                    let v = FixedAscii::<4096>::from_ascii(text.as_bytes()).unwrap();
                    put_scalar(&g, "model_toml", &v).unwrap();
                } else {
                    put_str(&g, "model_toml", text).unwrap();
                }
            }
            let rec = read(&p).unwrap();
            let got = &rec.truth.as_ref().unwrap().model_toml;
            assert_eq!(got.len(), text.len(), "case {k}");
            assert_eq!(got, text, "case {k}");
        }
        {
            let f = hdf5::File::open_rw(&p).unwrap();
            let ds = f.group("outputs").unwrap().dataset("accel_2").unwrap();
            ds.delete_attr("unit").unwrap();
            let v = VarLenAscii::from_ascii(&"g".repeat(100_000)).unwrap();
            put_scalar(&ds, "unit", &v).unwrap();
        }
        let e = crate::record::read(&p).unwrap_err().to_string();
        assert!(e.contains("channel accel_2: unit \"gggg"), "{e}");
        assert!(
            e.contains("…\" (100000 characters) is not a unit of accel"),
            "{e}"
        );
        assert!(e.len() < 400, "{} bytes: {}", e.len(), &e[..400]);
    }

    /// The fuzzer's out-of-memory input: two bytes of the shipped
    /// validation record's header changed so that a dataset declares
    /// 2.5 GB; refused before HDF5 allocates it.
    #[test]
    fn a_dataset_larger_than_its_file_is_refused() {
        let src = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/data/lanl8dof-bumper-validation.h5"
        );
        let mut bytes = std::fs::read(src).unwrap();
        let at = u32::from_le_bytes([0xcf, 0x32, 0x00, 0x26]) as usize % bytes.len();
        bytes[at..at + 2].copy_from_slice(&[0x96, 0x27]);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.h5");
        std::fs::write(&p, bytes).unwrap();
        let e = read_err(&p);
        assert!(
            e.contains("declares") && e.contains("corrupt or truncated"),
            "{e}"
        );
    }

    /// The fuzzer's second out-of-memory input (`58cb586bfa3a7ad18667`):
    /// six bytes of the validation record changed so that a `unit`
    /// attribute's string declares 1.7 GB characters, which libhdf5
    /// allocated 5 of (8.7 GB) to convert; refused before the read.
    #[test]
    fn a_string_of_giant_characters_is_refused_before_libhdf5_converts_it() {
        let src = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/data/lanl8dof-bumper-validation.h5"
        );
        let mut bytes = std::fs::read(src).unwrap();
        let at = u32::from_le_bytes([0x58, 0xcb, 0x58, 0x6b]) as usize % bytes.len();
        bytes[at..at + 6].copy_from_slice(&[0xfa, 0x3a, 0x7a, 0xd1, 0x86, 0x67]);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.h5");
        std::fs::write(&p, bytes).unwrap();
        let e = read_err(&p);
        assert!(
            e.contains("r.h5: ")
                && e.contains(
                    "attribute unit: a variable-length string of 1736888698-byte characters"
                ),
            "{e}"
        );
    }

    /// A fuzzed superblock (`84000000 0040`: two bytes at offset 132 of
    /// the validation record) makes libhdf5 ask for a 64 TB metadata
    /// buffer on opening; the allocator refuses it and the read is an
    /// error naming the file, at once.
    #[test]
    fn a_superblock_asking_for_terabytes_is_an_error() {
        let src = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/data/lanl8dof-bumper-validation.h5"
        );
        let mut bytes = std::fs::read(src).unwrap();
        bytes[132..134].copy_from_slice(&[0x00, 0x40]);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sb.h5");
        std::fs::write(&p, bytes).unwrap();
        let e = read_err(&p);
        assert!(e.contains("sb.h5: cannot open as HDF5"), "{e}");
    }

    /// A chunked, deflated channel that declares 2.4 GB in a file of a few
    /// kB: beyond what deflate can store in it, refused naming the channel.
    #[test]
    fn a_compressed_dataset_declaring_gigabytes_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("huge.h5");
        write_raw(&p, |f| {
            put_scalar(f, "fs", &100.0f64).unwrap();
            f.create_group("inputs").unwrap();
            let g = f.create_group("outputs").unwrap();
            g.new_dataset::<f64>()
                .chunk(4096)
                .deflate(4)
                .shape(300_000_000)
                .create("accel_3")
                .unwrap();
        });
        let len = std::fs::metadata(&p).unwrap().len();
        assert!(len < 100_000, "{len}");
        let e = read_err(&p);
        assert!(
            e.contains("huge.h5: channel accel_3: declares 300000000 values (shape [300000000], 2400000000 bytes stored)")
                && e.contains("1032 times what deflate stores in one byte"),
            "{e}"
        );
    }

    #[test]
    fn a_read_beyond_the_available_memory_is_refused() {
        let e = fits_in_memory(3_000_000_000, Some(2_000_000_000), "channel accel_1").unwrap_err();
        assert_eq!(
            e,
            "channel accel_1: reading it needs about 3.0 GB of memory; the machine has 2.0 GB available"
        );
        assert!(fits_in_memory(3_000_000_000, None, "x").is_ok());
        assert!(fits_in_memory(1_000, Some(2_000), "x").is_ok());
    }

    fn write_raw(p: &Path, build: impl FnOnce(&hdf5::File)) {
        let f = hdf5::File::create(p).unwrap();
        build(&f);
    }

    fn read_err(p: &Path) -> String {
        read(p).unwrap_err().to_string()
    }

    #[test]
    fn nan_names_channel_and_sample() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("nan.h5");
        let mut rec = record_with_truth();
        rec.outputs[1].data[17] = f64::NAN;
        write(&rec, &p).unwrap();
        let e = read_err(&p);
        assert!(e.contains("channel accel_10: sample 17 is NaN"), "{e}");
        assert!(e.contains("nan.h5"), "{e}");
    }

    #[test]
    fn bad_time_names_sample() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.h5");
        write_raw(&p, |f| {
            let mut t: Vec<f64> = (0..20).map(|k| k as f64 * 0.01).collect();
            t[12] = t[11];
            f.new_dataset_builder()
                .with_data(t.as_slice())
                .create("time")
                .unwrap();
        });
        assert!(read_err(&p).contains("time: sample 12 is not increasing"));
        let p = dir.path().join("u.h5");
        write_raw(&p, |f| {
            let mut t: Vec<f64> = (0..20).map(|k| k as f64 * 0.01).collect();
            t[7] += 0.002;
            f.new_dataset_builder()
                .with_data(t.as_slice())
                .create("time")
                .unwrap();
        });
        let e = read_err(&p);
        assert!(e.contains("time: sample 7 is not on a uniform grid"), "{e}");
    }

    #[test]
    fn fs_inconsistent_with_time_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("fs.h5");
        let mut rec = record_with_truth();
        rec.truth = None;
        write(&rec, &p).unwrap();
        {
            let f = hdf5::File::open_rw(&p).unwrap();
            f.delete_attr("fs").unwrap();
            put_scalar(&f, "fs", &600.0f64).unwrap();
        }
        let e = read_err(&p);
        assert!(e.contains("attribute fs = 600 Hz"), "{e}");
    }

    #[test]
    fn inconsistent_attributes_and_names() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.h5");
        write_raw(&p, |f| {
            put_scalar(f, "fs", &10.0f64).unwrap();
            f.create_group("inputs").unwrap();
            let g = f.create_group("outputs").unwrap();
            let ds = g
                .new_dataset_builder()
                .with_data(&[1.0f64; 4][..])
                .create("accel_5")
                .unwrap();
            put_str(&ds, "quantity", "disp").unwrap();
        });
        let e = read_err(&p);
        assert!(
            e.contains("channel accel_5") && e.contains("\"disp\""),
            "{e}"
        );

        let p = dir.path().join("b.h5");
        write_raw(&p, |f| {
            put_scalar(f, "fs", &10.0f64).unwrap();
            f.create_group("inputs").unwrap();
            let g = f.create_group("outputs").unwrap();
            g.new_dataset_builder()
                .with_data(&[1.0f64; 4][..])
                .create("temp_1")
                .unwrap();
        });
        assert!(read_err(&p).contains("unknown column \"temp_1\""));

        let p = dir.path().join("c.h5");
        write_raw(&p, |f| put_str(f, "format", "something-else").unwrap());
        assert!(read_err(&p).contains("something-else"));
    }

    #[test]
    fn missing_groups_and_bad_files_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("nogroup.h5");
        write_raw(&p, |f| {
            put_scalar(f, "fs", &10.0f64).unwrap();
            f.create_group("inputs").unwrap();
        });
        assert!(read_err(&p).contains("group /outputs is missing"));

        let p = dir.path().join("empty.h5");
        std::fs::write(&p, b"").unwrap();
        assert!(read_err(&p).contains("empty"));

        let p = dir.path().join("garbage.h5");
        let bytes: Vec<u8> = (0..4096u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
            .collect();
        std::fs::write(&p, bytes).unwrap();
        let e = read_err(&p);
        assert!(e.contains("garbage.h5") && e.contains("HDF5"), "{e}");

        let p = dir.path().join("absent.h5");
        assert!(read(&p).is_err());
    }

    #[test]
    fn unequal_lengths_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("len.h5");
        let mut rec = record_with_truth();
        rec.truth = None;
        rec.outputs[2].data.pop();
        // write() itself refuses it, so build the file by hand.
        assert!(write(&rec, &p).is_err());
        write_raw(&p, |f| {
            put_scalar(f, "fs", &10.0f64).unwrap();
            let g = f.create_group("inputs").unwrap();
            g.new_dataset_builder()
                .with_data(&[1.0f64; 4][..])
                .create("force_1")
                .unwrap();
            let g = f.create_group("outputs").unwrap();
            g.new_dataset_builder()
                .with_data(&[1.0f64; 3][..])
                .create("disp_1")
                .unwrap();
        });
        let e = read_err(&p);
        assert!(e.contains("channel disp_1 has 3 samples"), "{e}");
    }
}
