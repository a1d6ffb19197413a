//! Byte-level mutations of valid files and hostile values for flags and Python arguments.
//!
//! The mutations keep the workload small: a number is replaced by a value out of every range
//! (or a degenerate one), never by a large valid one, so that a probe that runs for long is a
//! hang of the program and not a big job it was asked for.

use rand::seq::IndexedRandom;
use rand::Rng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// The probes' random stream.
pub(crate) type FuzzRng = Xoshiro256PlusPlus;

/// Tokens inserted into files or put in place of a number: values beyond every limit, values
/// that are not numbers, separators and quotes of the formats read (CSV, TOML, JSON, V2),
/// control and non-ASCII characters, and bytes that are not UTF-8.
const TOKENS: &[&[u8]] = &[
    b"1e308",
    b"-1e308",
    b"1e309",
    b"-1e309",
    b"NaN",
    b"nan",
    b"-nan",
    b"inf",
    b"-inf",
    b"Infinity",
    b"-0",
    b"-0.0",
    b"0",
    b"-1",
    b"1e-320",
    b"4.9e-324",
    b"18446744073709551615",
    b"18446744073709551616",
    b"9223372036854775808",
    b"-9223372036854775809",
    b"4294967296",
    b"0x10",
    b"1_000",
    b"+5",
    b".",
    b",",
    b";",
    b"\"",
    b"'",
    b"\\",
    b"[",
    b"]",
    b"{",
    b"}",
    b"=",
    b"#",
    b"%",
    b"$(touch pwned)",
    b"\0",
    b"\xef\xbb\xbf",
    b"\xe2\x80\xae",
    b"\xc3\xa9",
    b"\xf0\x9f\x98\x80",
    b"\xff",
    b"\xc3",
    b"\r\n",
    b"\n",
    b"\r",
    b"\t",
    b" ",
    b"true",
    b"null",
    b"[]",
    b"{}",
    b"\"NaN\"",
    b"\"inf\"",
];

/// Values given to a flag (or its equivalent Python argument) instead of a valid one: beyond
/// every documented limit, not a number, empty, or spelled oddly. None is valid and large.
pub(crate) const FLAG_VALUES: &[&str] = &[
    "0",
    "-1",
    "-0",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e308",
    "1e309",
    "-1e308",
    "1e-320",
    "18446744073709551615",
    "18446744073709551616",
    "9223372036854775808",
    "-9223372036854775809",
    "4294967297",
    "20000001",
    "1e9",
    "",
    " ",
    "1,2",
    "0x10",
    "\u{ff11}",
    "a",
    "-",
    "=",
    "none",
    "1=2",
    "k1=nan",
    "k9=1",
    "1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1",
    "$(touch pwned)",
    "a\nb",
    "\u{202e}x",
];

/// One mutation of `bytes`, in place; returns what it did.
pub(crate) fn mutate(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    match rng.random_range(0..14) {
        0 => truncate(bytes, rng),
        1 => flip_bits(bytes, rng),
        2 => delete_span(bytes, rng),
        3 => insert_token(bytes, rng),
        4..=6 => replace_number(bytes, rng),
        7 => long_line(bytes, rng),
        8 => duplicate_line(bytes, rng),
        9 => delete_line(bytes, rng),
        10 => nest(bytes, rng),
        11 => swap_lines(bytes, rng),
        12 => repeat_tail(bytes, rng),
        _ => line_ends(bytes, rng),
    }
}

/// One to three mutations of `bytes`; returns what they did, joined.
pub(crate) fn mutate_some(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let n = match rng.random_range(0..10) {
        0..=6 => 1,
        7 | 8 => 2,
        _ => 3,
    };
    (0..n)
        .map(|_| mutate(bytes, rng))
        .collect::<Vec<_>>()
        .join("; ")
}

fn position(bytes: &[u8], rng: &mut FuzzRng) -> usize {
    rng.random_range(0..=bytes.len())
}

fn truncate(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let at = position(bytes, rng);
    bytes.truncate(at);
    format!("cut at byte {at}")
}

fn flip_bits(bytes: &mut [u8], rng: &mut FuzzRng) -> String {
    if bytes.is_empty() {
        return "nothing to flip".into();
    }
    let n = rng.random_range(1..=4);
    let mut at = Vec::with_capacity(n);
    for _ in 0..n {
        let i = rng.random_range(0..bytes.len());
        bytes[i] ^= 1 << rng.random_range(0..8);
        at.push(i.to_string());
    }
    format!("bits flipped at bytes {}", at.join(","))
}

fn delete_span(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let at = position(bytes, rng);
    let len = rng.random_range(1..=64).min(bytes.len() - at);
    bytes.drain(at..at + len);
    format!("{len} bytes deleted at {at}")
}

fn token(rng: &mut FuzzRng) -> &'static [u8] {
    TOKENS.choose(rng).expect("tokens")
}

fn shown(t: &[u8]) -> String {
    format!("{:?}", String::from_utf8_lossy(t))
}

fn insert_token(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let at = position(bytes, rng);
    let t = token(rng);
    bytes.splice(at..at, t.iter().copied());
    format!("{} inserted at {at}", shown(t))
}

/// The spans of numbers (digits with a sign, point and exponent) in `bytes`.
fn numbers(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_digit() {
            let mut start = i;
            if start > 0 && matches!(bytes[start - 1], b'-' | b'+') {
                start -= 1;
            }
            let mut end = i;
            while end < bytes.len()
                && (bytes[end].is_ascii_digit() || matches!(bytes[end], b'.' | b'e' | b'E'))
            {
                end += 1;
                if end < bytes.len()
                    && matches!(bytes[end - 1], b'e' | b'E')
                    && matches!(bytes[end], b'-' | b'+')
                {
                    end += 1;
                }
            }
            spans.push((start, end));
            i = end;
        } else {
            i += 1;
        }
    }
    spans
}

fn replace_number(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let spans = numbers(bytes);
    let Some(&(start, end)) = spans.choose(rng) else {
        return insert_token(bytes, rng);
    };
    let t = token(rng);
    let was = String::from_utf8_lossy(&bytes[start..end]).into_owned();
    bytes.splice(start..end, t.iter().copied());
    format!("number {was:?} at {start} replaced by {}", shown(t))
}

/// Start offsets of the lines of `bytes` (and the end).
fn line_starts(bytes: &[u8]) -> Vec<usize> {
    let mut starts = vec![0];
    starts.extend(
        bytes
            .iter()
            .enumerate()
            .filter(|(_, &b)| b == b'\n')
            .map(|(i, _)| i + 1),
    );
    if *starts.last().expect("one") != bytes.len() {
        starts.push(bytes.len());
    }
    starts
}

/// A random line of `bytes` as its span, without its newline.
fn some_line(bytes: &[u8], rng: &mut FuzzRng) -> (usize, usize, usize) {
    let starts = line_starts(bytes);
    if starts.len() < 2 {
        return (0, 0, 0);
    }
    let i = rng.random_range(0..starts.len() - 1);
    (i + 1, starts[i], starts[i + 1])
}

fn long_line(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let (line, start, end) = some_line(bytes, rng);
    let fill = *[b'a', b'9', b',', b' ', b'#']
        .choose(rng)
        .expect("fill bytes");
    let len = *[1_000usize, 100_000, 1_000_000]
        .choose(rng)
        .expect("lengths");
    let mut long = vec![fill; len];
    long.push(b'\n');
    bytes.splice(start..end, long);
    format!("line {line} replaced by {len} × {:?}", fill as char)
}

fn duplicate_line(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let (line, start, end) = some_line(bytes, rng);
    let copy = bytes[start..end].to_vec();
    let times = rng.random_range(1..=3);
    for _ in 0..times {
        bytes.splice(end..end, copy.iter().copied());
    }
    format!("line {line} repeated {times} more times")
}

fn delete_line(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let (line, start, end) = some_line(bytes, rng);
    bytes.drain(start..end);
    format!("line {line} deleted")
}

fn nest(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let depth = *[64usize, 10_000, 100_000].choose(rng).expect("depths");
    let (open, close) = *[(b'[', b']'), (b'{', b'}')].choose(rng).expect("brackets");
    // After a `=` or `:` when there is one, so the nesting is a value.
    let values: Vec<usize> = bytes
        .iter()
        .enumerate()
        .filter(|(_, &b)| b == b'=' || b == b':')
        .map(|(i, _)| i + 1)
        .collect();
    let at = match values.choose(rng) {
        Some(&at) => at,
        None => position(bytes, rng),
    };
    let mut nested = vec![open; depth];
    nested.extend(std::iter::repeat_n(close, depth));
    bytes.splice(at..at, nested);
    format!("{depth} nested {:?} inserted at {at}", open as char)
}

fn swap_lines(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let starts = line_starts(bytes);
    if starts.len() < 3 {
        return delete_line(bytes, rng);
    }
    let a = rng.random_range(0..starts.len() - 2);
    let b = rng.random_range(a + 1..starts.len() - 1);
    let la = bytes[starts[a]..starts[a + 1]].to_vec();
    let lb = bytes[starts[b]..starts[b + 1]].to_vec();
    let mut out = bytes[..starts[a]].to_vec();
    out.extend_from_slice(&lb);
    out.extend_from_slice(&bytes[starts[a + 1]..starts[b]]);
    out.extend_from_slice(&la);
    out.extend_from_slice(&bytes[starts[b + 1]..]);
    *bytes = out;
    format!("lines {} and {} swapped", a + 1, b + 1)
}

/// The last lines repeated many times: a longer table of the same kind (at most a few MB, a
/// small workload still).
fn repeat_tail(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    let starts = line_starts(bytes);
    let from = starts[starts.len().saturating_sub(3)];
    let tail = bytes[from..].to_vec();
    if tail.is_empty() {
        return insert_token(bytes, rng);
    }
    let times = (2_000_000 / tail.len()).clamp(1, 5_000);
    for _ in 0..times {
        bytes.extend_from_slice(&tail);
    }
    format!("last lines repeated {times} times")
}

fn line_ends(bytes: &mut Vec<u8>, rng: &mut FuzzRng) -> String {
    match rng.random_range(0..4) {
        0 => {
            let mut out = Vec::with_capacity(bytes.len() * 2);
            for &b in bytes.iter() {
                if b == b'\n' {
                    out.push(b'\r');
                }
                out.push(b);
            }
            *bytes = out;
            "CRLF line ends".into()
        }
        1 => {
            bytes.retain(|&b| b != b'\n');
            "newlines removed".into()
        }
        2 => {
            bytes.splice(0..0, *b"\xef\xbb\xbf\xef\xbb\xbf");
            "two byte-order marks at the start".into()
        }
        _ => {
            bytes.clear();
            "emptied".into()
        }
    }
}

/// A hostile value for a flag.
pub(crate) fn flag_value(rng: &mut FuzzRng) -> String {
    if rng.random_bool(0.05) {
        return "9".repeat(400);
    }
    FLAG_VALUES.choose(rng).expect("flag values").to_string()
}

/// A hostile value for a Python argument, as the JSON the probe's script decodes
/// (`{"$f": "nan"}` is the float NaN, `{"$i": "…"}` an integer of any size).
pub(crate) fn python_value(rng: &mut FuzzRng) -> serde_json::Value {
    use serde_json::json;
    let values = [
        json!(0),
        json!(-1),
        json!({"$f": "-0.0"}),
        json!({"$f": "nan"}),
        json!({"$f": "inf"}),
        json!({"$f": "-inf"}),
        json!(1e308),
        json!(-1e308),
        json!(5e-324),
        json!({"$i": "18446744073709551616"}),
        json!({"$i": "9223372036854775808"}),
        json!({"$i": "-9223372036854775809"}),
        json!({"$i": "100000000000000000000000000000"}),
        json!(4294967297u64),
        json!(20000001),
        json!(""),
        json!("x"),
        json!("nan"),
        json!("a\nb"),
        json!(null),
        json!(true),
        json!([]),
        json!([1, 2]),
        json!({}),
    ];
    values.choose(rng).expect("values").clone()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn numbers_are_found_with_sign_point_and_exponent() {
        let text = b"a = -1.5e-3, b = 20\nx7";
        let spans: Vec<&[u8]> = numbers(text)
            .into_iter()
            .map(|(s, e)| &text[s..e])
            .collect();
        assert_eq!(spans, [&b"-1.5e-3"[..], b"20", b"7"]);
    }

    #[test]
    fn every_mutation_runs_on_empty_and_small_inputs() {
        let mut rng = FuzzRng::seed_from_u64(3);
        for _ in 0..2_000 {
            let mut empty = Vec::new();
            mutate(&mut empty, &mut rng);
            let mut small = b"t,a\n0,1\n0.5,2\n".to_vec();
            mutate(&mut small, &mut rng);
            assert!(small.len() < 20_000_000);
        }
    }

    #[test]
    fn swapping_two_lines_keeps_every_byte() {
        let mut rng = FuzzRng::seed_from_u64(1);
        let mut text = b"a\nbb\nccc\ndddd\n".to_vec();
        swap_lines(&mut text, &mut rng);
        let mut sorted = text.clone();
        sorted.sort_unstable();
        let mut want = b"a\nbb\nccc\ndddd\n".to_vec();
        want.sort_unstable();
        assert_eq!(sorted, want);
    }
}
