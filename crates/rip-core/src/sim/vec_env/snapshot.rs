//! The byte form of a [`VecEnv`](super::VecEnv) ([`VecEnv::to_bytes`](super::VecEnv::to_bytes)):
//! what `pickle` and `copy.deepcopy` of `riprs.envs` carry, so that a restored environment
//! continues exactly as the original would. Little-endian fixed-width fields behind a magic
//! and a version; every read is checked, so bytes that are not a saved environment are an
//! error naming `state`, never a panic.

use super::config::bad;
use crate::error::{Result, RipError};

/// Leads every saved environment: bytes from anywhere else are refused at once.
const MAGIC: &[u8; 8] = b"riprsenv";
/// Bumped whenever the layout changes; older layouts are refused rather than misread.
const VERSION: u8 = 1;

fn corrupt(reason: &str) -> RipError {
    bad("state", format!("not a saved riprs environment ({reason})"))
}

/// Appends fields.
pub(super) struct Writer(Vec<u8>);

impl Writer {
    pub(super) fn new() -> Self {
        let mut w = Self(Vec::new());
        w.0.extend_from_slice(MAGIC);
        w.u8(VERSION);
        w
    }

    pub(super) fn finish(self) -> Vec<u8> {
        self.0
    }

    pub(super) fn u8(&mut self, v: u8) {
        self.0.push(v);
    }

    pub(super) fn bool(&mut self, v: bool) {
        self.u8(u8::from(v));
    }

    pub(super) fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    pub(super) fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    pub(super) fn u128(&mut self, v: u128) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    pub(super) fn usize(&mut self, v: usize) {
        self.u64(v as u64);
    }

    pub(super) fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }

    pub(super) fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.f64(*x);
        }
    }

    pub(super) fn bytes(&mut self, v: &[u8]) {
        self.0.extend_from_slice(v);
    }

    pub(super) fn opt_pair(&mut self, v: Option<[f64; 2]>) {
        self.bool(v.is_some());
        self.f64s(&v.unwrap_or_default());
    }
}

/// Reads fields back, each checked.
pub(super) struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    pub(super) fn new(bytes: &'a [u8]) -> Result<Self> {
        let mut r = Self(bytes);
        if r.take(MAGIC.len())? != MAGIC {
            return Err(corrupt("no riprs environment header"));
        }
        let version = r.u8()?;
        if version != VERSION {
            return Err(corrupt(&format!(
                "layout version {version}, this riprs reads {VERSION}"
            )));
        }
        Ok(r)
    }

    /// Fails unless every byte was read.
    pub(super) fn finish(self) -> Result<()> {
        if self.0.is_empty() {
            Ok(())
        } else {
            Err(corrupt("trailing bytes"))
        }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        if self.0.len() < n {
            return Err(corrupt("truncated"));
        }
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Ok(head)
    }

    pub(super) fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        Ok(self.take(N)?.try_into().expect("took N bytes"))
    }

    pub(super) fn u8(&mut self) -> Result<u8> {
        Ok(self.array::<1>()?[0])
    }

    pub(super) fn bool(&mut self) -> Result<bool> {
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(corrupt("a flag that is neither 0 nor 1")),
        }
    }

    pub(super) fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array()?))
    }

    pub(super) fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array()?))
    }

    pub(super) fn u128(&mut self) -> Result<u128> {
        Ok(u128::from_le_bytes(self.array()?))
    }

    /// A count, at most `max`.
    pub(super) fn usize(&mut self, max: usize) -> Result<usize> {
        match usize::try_from(self.u64()?) {
            Ok(v) if v <= max => Ok(v),
            _ => Err(corrupt("a count out of range")),
        }
    }

    pub(super) fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_bits(self.u64()?))
    }

    pub(super) fn f64s<const N: usize>(&mut self) -> Result<[f64; N]> {
        let mut v = [0.0; N];
        for x in &mut v {
            *x = self.f64()?;
        }
        Ok(v)
    }

    pub(super) fn opt_pair(&mut self) -> Result<Option<[f64; 2]>> {
        let some = self.bool()?;
        let v = self.f64s::<2>()?;
        Ok(some.then_some(v))
    }

    /// A length for a list of `item_bytes`-byte items: never more than the bytes left hold.
    pub(super) fn len(&mut self, item_bytes: usize) -> Result<usize> {
        let n = self.usize(usize::MAX)?;
        if n.saturating_mul(item_bytes) > self.0.len() {
            return Err(corrupt("truncated"));
        }
        Ok(n)
    }
}

/// The error of a snapshot that reads but holds a value no environment can have.
pub(super) fn invalid(reason: &str) -> RipError {
    corrupt(reason)
}
