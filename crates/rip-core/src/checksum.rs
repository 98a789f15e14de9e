//! The checksum of the tuning record's entries: 64-bit FNV-1a, which detects edits, not
//! tampering.

/// 64-bit FNV-1a over `parts` in order, written `fnv1a64:` and 16 hex digits
/// ([`crate::preflight::design_checksum`], [`crate::swingup::feasibility_inputs`]).
pub fn fnv1a64(parts: &[&[u8]]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in parts.iter().flat_map(|p| p.iter()) {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("fnv1a64:{h:016x}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn published_fnv1a64_vectors() {
        // From the FNV reference test suite (Fowler, Noll, Vo): "" and "a".
        assert_eq!(super::fnv1a64(&[]), "fnv1a64:cbf29ce484222325");
        assert_eq!(super::fnv1a64(&[b"a"]), "fnv1a64:af63dc4c8601ec8c");
        assert_eq!(
            super::fnv1a64(&[b"foo", b"bar"]),
            super::fnv1a64(&[b"foobar"])
        );
    }
}
