//! Moving particles' slices into and out of the lanes of a [`Pack`] (the batch layer's gather and
//! scatter). Lane `b` of entry `i` of a pack slice is entry `i` of particle `b`'s slice.

use crate::real::{Pack, PACK_LANES};
use wide::f64x4;

/// The 4 × 4 transpose: lane `j` of output `i` is lane `i` of input `j`.
#[inline(always)]
fn transpose4(v: [[f64; 4]; 4]) -> [f64x4; 4] {
    std::array::from_fn(|i| f64x4::new([v[0][i], v[1][i], v[2][i], v[3][i]]))
}

/// `out[i]` lane `b` = `src[b][i]` for every `i < out.len()`.
#[inline]
pub fn gather(out: &mut [Pack], src: [&[f64]; PACK_LANES]) {
    let len = out.len();
    let blocks = len / 4;
    for blk in 0..blocks {
        let i = 4 * blk;
        let rows: [[f64; 4]; 4] =
            std::array::from_fn(|b| [src[b][i], src[b][i + 1], src[b][i + 2], src[b][i + 3]]);
        let t = transpose4(rows);
        for (o, v) in out[i..i + 4].iter_mut().zip(t) {
            *o = Pack(v);
        }
    }
    for i in 4 * blocks..len {
        out[i] = Pack(f64x4::new([src[0][i], src[1][i], src[2][i], src[3][i]]));
    }
}

/// `dst[b][i]` = lane `b` of `src[i]`, for the lanes `b` with `take[b]`.
///
/// When every lane is taken (the usual case) the pack slice is transposed four entries at a time
/// and each particle receives four contiguous values per block, instead of four passes that
/// each extract one lane of every pack.
#[inline]
pub fn scatter(src: &[Pack], dst: [Option<&mut [f64]>; PACK_LANES]) {
    if dst.iter().all(Option::is_some) {
        let mut d = dst.map(|d| d.expect("every lane is taken"));
        let len = src.len().min(d.iter().map(|x| x.len()).min().unwrap_or(0));
        let blocks = len / 4;
        for blk in 0..blocks {
            let i = 4 * blk;
            let rows: [[f64; 4]; 4] = std::array::from_fn(|j| *src[i + j].0.as_array_ref());
            let t = transpose4(rows);
            for (b, lane) in d.iter_mut().enumerate() {
                lane[i..i + 4].copy_from_slice(t[b].as_array_ref());
            }
        }
        for i in 4 * blocks..len {
            let v = src[i].0.as_array_ref();
            for (b, lane) in d.iter_mut().enumerate() {
                lane[i] = v[b];
            }
        }
        return;
    }
    for (b, d) in dst.into_iter().enumerate() {
        if let Some(d) = d {
            for (o, v) in d.iter_mut().zip(src) {
                *o = v.0.as_array_ref()[b];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Real;

    #[test]
    fn gather_then_scatter_round_trips() {
        let parts: Vec<Vec<f64>> = (0..4)
            .map(|b| (0..7).map(|i| (10 * b + i) as f64).collect())
            .collect();
        let mut packed = vec![Pack::splat(0.0); 7];
        gather(&mut packed, std::array::from_fn(|b| parts[b].as_slice()));
        assert_eq!(packed[5].lane(2), 25.0);
        let mut back = vec![vec![0.0; 7]; 4];
        let mut it = back.iter_mut();
        let dst = std::array::from_fn(|_| Some(it.next().unwrap().as_mut_slice()));
        scatter(&packed, dst);
        assert_eq!(back, parts);
        // Some lanes only: the others are left untouched.
        let mut partial = vec![vec![-1.0; 7]; 4];
        let mut it = partial.iter_mut().enumerate();
        let dst = std::array::from_fn(|_| {
            let (b, v) = it.next().unwrap();
            (b % 2 == 0).then_some(v.as_mut_slice())
        });
        scatter(&packed, dst);
        assert_eq!(partial[0], parts[0]);
        assert_eq!(partial[1], vec![-1.0; 7]);
        assert_eq!(partial[2], parts[2]);
    }
}
