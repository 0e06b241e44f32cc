//! Row-major dense matrices: the layout of back-substitution, where every
//! row is one linear bound and every operation walks a row.
//!
//! nalgebra's matrices are column-major; a bound's row is then strided, and
//! the per-row work of CROWN (offsets, error terms, relaxations) was spent
//! copying rows out. [`Rows`] keeps each row contiguous and offers the few
//! operations back-substitution needs. Products with a layer's weights read
//! the weights' columns (contiguous in nalgebra) as plain dot products for
//! small sizes, and hand larger ones to nalgebra's blocked product
//! (matrixmultiply) on a transposed view, so wide networks run at the
//! speed of a matrix multiply. Either way each product is a rounded `f64`
//! result; the callers account for its rounding error.

use nalgebra::{DMatrix, DMatrixView, DMatrixViewMut};

/// A `rows × cols` matrix stored row after row.
#[derive(Clone, Debug, PartialEq)]
pub struct Rows {
    rows: usize,
    cols: usize,
    data: Vec<f64>,
}

/// Products at least this large (multiply-adds) go to the blocked product.
const BLOCKED: usize = 16 * 1024;

impl Rows {
    /// The zero matrix.
    pub fn zeros(rows: usize, cols: usize) -> Rows {
        Rows {
            rows,
            cols,
            data: vec![0.0; rows * cols],
        }
    }

    /// An empty matrix whose storage can hold `elems` numbers without
    /// growing (a buffer for [`Rows::mul_into`]).
    pub fn with_capacity(elems: usize) -> Rows {
        Rows {
            rows: 0,
            cols: 0,
            data: Vec::with_capacity(elems),
        }
    }

    /// Make room for `elems` numbers in all.
    pub fn reserve_total(&mut self, elems: usize) {
        self.data.reserve(elems.saturating_sub(self.data.len()));
    }

    /// A matrix from its rows, stored one after another (`data.len()` must be `rows · cols`).
    pub fn from_row_major(rows: usize, cols: usize, data: Vec<f64>) -> Rows {
        assert_eq!(
            data.len(),
            rows * cols,
            "row-major data of the wrong length"
        );
        Rows { rows, cols, data }
    }

    /// Number of rows.
    pub fn nrows(&self) -> usize {
        self.rows
    }

    /// Number of columns.
    pub fn ncols(&self) -> usize {
        self.cols
    }

    /// Row `r`.
    #[inline]
    pub fn row(&self, r: usize) -> &[f64] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }

    /// Row `r`, mutable.
    #[inline]
    pub fn row_mut(&mut self, r: usize) -> &mut [f64] {
        &mut self.data[r * self.cols..(r + 1) * self.cols]
    }

    /// Entry `(r, c)`.
    #[inline]
    pub fn get(&self, r: usize, c: usize) -> f64 {
        self.data[r * self.cols + c]
    }

    /// Every row in order.
    pub fn iter_rows(&self) -> impl Iterator<Item = &[f64]> {
        (0..self.rows).map(move |r| self.row(r))
    }

    /// The same matrix in nalgebra's layout.
    pub fn to_dmatrix(&self) -> DMatrix<f64> {
        DMatrix::from_row_slice(self.rows, self.cols, &self.data)
    }

    /// `self` above `other` (same number of columns).
    pub fn stacked(&self, other: &Rows) -> Rows {
        assert_eq!(self.cols, other.cols, "stacking rows of different widths");
        let mut data = Vec::with_capacity(self.data.len() + other.data.len());
        data.extend_from_slice(&self.data);
        data.extend_from_slice(&other.data);
        Rows::from_row_major(self.rows + other.rows, self.cols, data)
    }

    /// The first `at` rows and the rest.
    pub fn split_rows(mut self, at: usize) -> (Rows, Rows) {
        let at = at.min(self.rows);
        let rest = self.data.split_off(at * self.cols);
        let tail = Rows::from_row_major(self.rows - at, self.cols, rest);
        self.rows = at;
        (self, tail)
    }

    /// The first `keep` columns.
    pub fn first_columns(&self, keep: usize) -> Rows {
        let mut data = Vec::with_capacity(self.rows * keep);
        for row in self.iter_rows() {
            data.extend_from_slice(&row[..keep]);
        }
        Rows::from_row_major(self.rows, keep, data)
    }

    /// Entry-wise absolute values.
    pub fn abs(&self) -> Rows {
        Rows {
            rows: self.rows,
            cols: self.cols,
            data: self.data.iter().map(|v| v.abs()).collect(),
        }
    }

    /// Negate every entry (exact).
    pub fn negate(&mut self) {
        self.data.iter_mut().for_each(|v| *v = -*v);
    }

    /// Entry-wise sum (rounded; the caller accounts for the rounding).
    pub fn plus(&self, other: &Rows) -> Rows {
        assert_eq!((self.rows, self.cols), (other.rows, other.cols));
        Rows {
            rows: self.rows,
            cols: self.cols,
            data: self
                .data
                .iter()
                .zip(&other.data)
                .map(|(a, b)| a + b)
                .collect(),
        }
    }

    /// The product `self · m` (`m` is `cols × p`), rounded: each entry is a
    /// floating-point sum of `cols` products, in an order that depends only
    /// on the sizes (the caller accounts for the rounding error).
    pub fn mul(&self, m: &DMatrix<f64>) -> Rows {
        let mut out = Rows::zeros(0, 0);
        self.mul_into(m, &mut out);
        out
    }

    /// [`Rows::mul`] into `out`, reusing its storage.
    pub fn mul_into(&self, m: &DMatrix<f64>, out: &mut Rows) {
        self.mul_cols_into(m.as_slice(), m.nrows(), m.ncols(), out);
    }

    /// [`Rows::mul_into`] for the `n × p` matrix stored column after column
    /// in `m` (nalgebra's layout).
    pub fn mul_cols_into(&self, m: &[f64], n: usize, p: usize, out: &mut Rows) {
        assert_eq!(self.cols, n, "product of mismatched sizes");
        assert_eq!(m.len(), n * p, "column-major data of the wrong length");
        let k = self.rows;
        out.rows = k;
        out.cols = p;
        out.data.clear();
        if k == 0 || n == 0 || p == 0 {
            out.data.resize(k * p, 0.0);
            return;
        }
        if k.saturating_mul(n).saturating_mul(p) >= BLOCKED && n >= 8 {
            // outᵀ = mᵀ · selfᵀ, where selfᵀ is `self`'s storage read
            // column-major and outᵀ's column-major storage is `out`
            // row-major
            out.data.resize(k * p, 0.0);
            let st = DMatrixView::from_slice(&self.data, n, k);
            let mt = DMatrixView::from_slice(m, n, p).transpose();
            let mut ot = DMatrixViewMut::from_slice(&mut out.data, p, k);
            ot.gemm(1.0, &mt, &st, 0.0);
            return;
        }
        // four rows at a time: four independent sums per column keep the
        // floating-point adder busy (each sum still runs over the column
        // in order, so the result is the plain dot product's)
        out.data.resize(k * p, 0.0);
        let cols: &[f64] = m;
        let mut blocks = self.data.chunks_exact(4 * n);
        let mut outs = out.data.chunks_exact_mut(4 * p);
        for (rows, o) in (&mut blocks).zip(&mut outs) {
            let (r0, rest) = rows.split_at(n);
            let (r1, rest) = rest.split_at(n);
            let (r2, r3) = rest.split_at(n);
            for (i, col) in cols.chunks_exact(n).enumerate() {
                let (mut s0, mut s1, mut s2, mut s3) = (0.0, 0.0, 0.0, 0.0);
                for j in 0..n {
                    let c = col[j];
                    s0 += r0[j] * c;
                    s1 += r1[j] * c;
                    s2 += r2[j] * c;
                    s3 += r3[j] * c;
                }
                o[i] = s0;
                o[p + i] = s1;
                o[2 * p + i] = s2;
                o[3 * p + i] = s3;
            }
        }
        for (row, o) in blocks
            .remainder()
            .chunks_exact(n)
            .zip(outs.into_remainder().chunks_exact_mut(p))
        {
            for (oi, col) in o.iter_mut().zip(cols.chunks_exact(n)) {
                let mut s = 0.0;
                for (a, b) in row.iter().zip(col) {
                    s += a * b;
                }
                *oi = s;
            }
        }
    }

    /// Rows `a` and `b` (`a < b`), both mutable.
    pub fn rows_pair_mut(&mut self, a: usize, b: usize) -> (&mut [f64], &mut [f64]) {
        assert!(a < b && b < self.rows, "rows out of order");
        let (head, tail) = self.data.split_at_mut(b * self.cols);
        (
            &mut head[a * self.cols..(a + 1) * self.cols],
            &mut tail[..self.cols],
        )
    }

    /// The same rows with their columns moved: the columns are the entries
    /// `from` (all `full` of them with `None`) of a longer vector, and come
    /// out as its entries `to` (all with `None`); an entry not in `from` is 0.
    pub fn columns_moved(&self, from: Option<&[usize]>, to: Option<&[usize]>, full: usize) -> Rows {
        let width = to.map_or(full, <[usize]>::len);
        let mut out = Rows::zeros(self.rows, width);
        let mut wide = vec![0.0; full];
        for (r, row) in self.iter_rows().enumerate() {
            wide.iter_mut().for_each(|v| *v = 0.0);
            match from {
                None => wide.copy_from_slice(row),
                Some(f) => f.iter().zip(row).for_each(|(&j, &v)| wide[j] = v),
            }
            let o = out.row_mut(r);
            match to {
                None => o.copy_from_slice(&wide),
                Some(t) => o.iter_mut().zip(t).for_each(|(v, &j)| *v = wide[j]),
            }
        }
        out
    }
}

impl From<&DMatrix<f64>> for Rows {
    fn from(m: &DMatrix<f64>) -> Rows {
        let (rows, cols) = m.shape();
        let mut data = Vec::with_capacity(rows * cols);
        for r in 0..rows {
            data.extend(m.row(r).iter());
        }
        Rows { rows, cols, data }
    }
}

impl From<DMatrix<f64>> for Rows {
    fn from(m: DMatrix<f64>) -> Rows {
        Rows::from(&m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ravel_base::rng::Rng;

    #[test]
    fn products_agree_with_nalgebra_on_both_paths() {
        let mut rng = Rng::new(7);
        for (k, n, p) in [
            (3, 2, 5),
            (1, 1, 1),
            (40, 30, 20),
            (64, 64, 64),
            (96, 64, 5),
            (6, 48, 64),
            (32, 48, 64),
            (6, 96, 96),
            (2, 0, 3),
            (0, 4, 2),
        ] {
            let a = DMatrix::from_fn(k, n, |_, _| rng.uniform(-2.0, 2.0));
            let b = DMatrix::from_fn(n, p, |_, _| rng.uniform(-2.0, 2.0));
            let want = &a * &b;
            let got = Rows::from(&a).mul(&b).to_dmatrix();
            assert_eq!(got.shape(), want.shape());
            for (g, w) in got.iter().zip(want.iter()) {
                assert!((g - w).abs() <= 1e-12 * (1.0 + w.abs()), "{g} vs {w}");
            }
        }
    }

    #[test]
    fn layout_round_trips() {
        let m = DMatrix::from_row_slice(2, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let r = Rows::from(&m);
        assert_eq!(r.row(1), &[4.0, 5.0, 6.0]);
        assert_eq!(r.get(0, 2), 3.0);
        assert_eq!(r.to_dmatrix(), m);
        assert_eq!(r.first_columns(2).row(1), &[4.0, 5.0]);
        assert_eq!(Rows::zeros(3, 0).iter_rows().count(), 3);
    }
}
