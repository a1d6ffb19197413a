//! Filter partitions of the Bouc–Wen chain (SPEC §5).
