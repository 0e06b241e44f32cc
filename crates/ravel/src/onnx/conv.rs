//! `Conv`, `AveragePool` and `GlobalAveragePool` as exact dense affine
//! layers on the flat row-major `(C, H, W)` value (the batch dimension as 1).
//!
//! The window's geometry (strides, dilations, pads or `auto_pad`) is read
//! and checked in 128-bit arithmetic (attribute values are `i64`, so no
//! product or sum of two of them overflows), the output size is checked
//! against [`MAX_WIDTH`] and the dense matrix against the limit on weights
//! before anything is allocated, and only the kernel taps that fall inside
//! the input are visited (at most `C·H·W` per output), so hostile sizes
//! cost nothing. A convolution's matrix holds the stored kernel weights
//! themselves (one per tap, zeros elsewhere): exact. An average's weight is
//! the `f64` nearest to `1/k` (`k` the number of elements it divides by),
//! as `Div` by a constant is read.

use nalgebra::{DMatrix, DVector};

use super::proto::NodeProto;
use super::{attr, attr_i, err, node_label, shape_text, Lowering, OnnxError, OnnxErrorKind};
use ravel_base::limits::MAX_WIDTH;
use ravel_syntax::diag::sanitize;

/// The geometry of a 2-D sliding window on a value of shape `[1, C, H, W]`.
struct Window {
    /// Input channels `C`.
    channels: usize,
    /// Input height and width.
    size: [usize; 2],
    /// Kernel extent along each axis (taps, before dilation).
    kernel: [i128; 2],
    strides: [i128; 2],
    dilations: [i128; 2],
    /// Padding before the first row and column.
    begin: [i128; 2],
    /// Output height and width.
    out: [usize; 2],
}

impl Window {
    /// The taps of output position `o` along `axis`: (kernel index, input
    /// index) for every kernel index whose input index lies inside the
    /// input (taps on the padding read zeros and are left out).
    fn taps(&self, axis: usize, o: usize) -> Vec<(usize, usize)> {
        let (Some(&k), Some(&s), Some(&d), Some(&b), Some(&size)) = (
            self.kernel.get(axis),
            self.strides.get(axis),
            self.dilations.get(axis),
            self.begin.get(axis),
            self.size.get(axis),
        ) else {
            return Vec::new();
        };
        // the input index of kernel index 0
        let start = o as i128 * s - b;
        // kernel indices j with 0 ≤ start + j·d ≤ size − 1 (d ≥ 1)
        let lo = if start >= 0 { 0 } else { (-start + d - 1) / d };
        let hi = (size as i128 - 1 - start).div_euclid(d).min(k - 1);
        let mut out = Vec::new();
        let mut j = lo;
        while j <= hi {
            if let (Ok(kj), Ok(i)) = (usize::try_from(j), usize::try_from(start + j * d)) {
                out.push((kj, i));
            }
            j += 1;
        }
        out
    }

    /// Output elements per channel.
    fn plane(&self) -> usize {
        self.out.iter().product()
    }

    /// Input elements.
    fn inputs(&self) -> usize {
        self.channels * self.size.iter().product::<usize>()
    }
}

/// An optional list-of-integers attribute of `len` entries.
fn ints(n: &NodeProto, name: &str, len: usize) -> Result<Option<Vec<i64>>, OnnxError> {
    match attr(n, name) {
        None => Ok(None),
        Some(a) if a.ints.len() == len => Ok(Some(a.ints.clone())),
        Some(a) => Err(err(
            OnnxErrorKind::Malformed,
            format!(
                "{} has {} values of '{name}' for a 2-D window; it needs {len}",
                node_label(n),
                a.ints.len()
            ),
            "the model's attributes are inconsistent: re-export it",
        )),
    }
}

fn malformed(n: &NodeProto, what: String) -> OnnxError {
    err(
        OnnxErrorKind::Malformed,
        format!("{} {what}", node_label(n)),
        "the model's attributes or shapes are inconsistent: re-export it",
    )
}

impl Lowering {
    /// The running value as `[1, C, H, W]`, or the error naming node `n`.
    fn image(&self, n: &NodeProto) -> Result<[usize; 3], OnnxError> {
        let shape = self.value_shape(n)?;
        match shape.as_slice() {
            [1, c, h, w] if *c > 0 && *h > 0 && *w > 0 => Ok([*c, *h, *w]),
            _ => Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} reads a value of shape {}; ravel supports 2-D windows on one image of shape [1, C, H, W]",
                    node_label(n),
                    shape_text(&shape)
                ),
                "export the network with a 4-D NCHW input of batch size 1 (a Reshape to [1, C, H, W] before the first Conv)",
            )),
        }
    }

    /// The window of node `n` with the given kernel extent on the running
    /// value, from its `strides`, `dilations`, `pads` and `auto_pad`, with
    /// `out_channels` output channels (checked against [`MAX_WIDTH`]).
    fn window(
        &self,
        n: &NodeProto,
        kernel: [i64; 2],
        out_channels: usize,
    ) -> Result<Window, OnnxError> {
        let [channels, h, w] = self.image(n)?;
        let strides = ints(n, "strides", 2)?.unwrap_or_else(|| vec![1, 1]);
        let dilations = ints(n, "dilations", 2)?.unwrap_or_else(|| vec![1, 1]);
        let pads = ints(n, "pads", 4)?;
        if let Some(s) = strides.iter().find(|s| **s < 1) {
            return Err(malformed(n, format!("has stride {s}; strides must be ≥ 1")));
        }
        if let Some(d) = dilations.iter().find(|d| **d < 1) {
            return Err(malformed(
                n,
                format!("has dilation {d}; dilations must be ≥ 1"),
            ));
        }
        if let Some(k) = kernel.iter().find(|k| **k < 1) {
            return Err(malformed(
                n,
                format!("has a kernel extent of {k}; it must be ≥ 1"),
            ));
        }
        if let Some(p) = pads.iter().flatten().find(|p| **p < 0) {
            return Err(malformed(n, format!("has a negative pad {p}")));
        }
        let auto_pad = attr(n, "auto_pad")
            .and_then(|a| a.s.as_ref())
            .map(|s| String::from_utf8_lossy(s).into_owned())
            .unwrap_or_else(|| "NOTSET".into());
        if auto_pad != "NOTSET" && pads.as_ref().is_some_and(|p| p.iter().any(|v| *v != 0)) {
            return Err(malformed(
                n,
                format!("sets both pads and auto_pad = {}", sanitize(&auto_pad)),
            ));
        }
        let pads = pads.unwrap_or_else(|| vec![0; 4]);
        let size = [h, w];
        let mut begin = [0i128; 2];
        let mut out = [0usize; 2];
        for axis in 0..2 {
            let at = |v: &[i64], i: usize| v.get(i).copied().unwrap_or(0) as i128;
            let (k, s, d) = (at(&kernel, axis), at(&strides, axis), at(&dilations, axis));
            let x = size.get(axis).copied().unwrap_or(0) as i128;
            // the window's extent, dilation included
            let extent = (k - 1) * d + 1;
            let (b, e) = match auto_pad.as_str() {
                "NOTSET" => (at(&pads, axis), at(&pads, axis + 2)),
                "VALID" => (0, 0),
                "SAME_UPPER" | "SAME_LOWER" => {
                    // out = ⌈x/s⌉, padded so that the last window ends inside
                    let o = (x + s - 1) / s;
                    let total = ((o - 1) * s + extent - x).max(0);
                    let small = total / 2;
                    if auto_pad == "SAME_UPPER" {
                        (small, total - small)
                    } else {
                        (total - small, small)
                    }
                }
                other => {
                    return Err(malformed(
                        n,
                        format!(
                            "has auto_pad = '{}', which is not an ONNX value",
                            sanitize(other)
                        ),
                    ))
                }
            };
            let padded = x + b + e;
            if extent > padded {
                return Err(malformed(
                    n,
                    format!(
                        "has a window of extent {extent} (kernel {k}, dilation {d}) on an axis of {x} padded to {padded}: larger than the padded input",
                    ),
                ));
            }
            let o = (padded - extent) / s + 1;
            if let (Some(slot), Some(bslot)) = (out.get_mut(axis), begin.get_mut(axis)) {
                *slot = usize::try_from(o).unwrap_or(usize::MAX);
                *bslot = b;
            }
        }
        let width = out
            .iter()
            .try_fold(out_channels as u64, |a, d| a.checked_mul(*d as u64))
            .filter(|v| *v <= MAX_WIDTH);
        if width.is_none() {
            let shown: Vec<String> = [out_channels, out[0], out[1]]
                .iter()
                .map(|d| {
                    if *d == usize::MAX {
                        "huge".into()
                    } else {
                        d.to_string()
                    }
                })
                .collect();
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} gives a value of shape [1, {}], wider than ravel's limit of {MAX_WIDTH}",
                    node_label(n),
                    shown.join(", ")
                ),
                "ravel verifies networks whose layers have at most 4096 neurons",
            ));
        }
        Ok(Window {
            channels,
            size,
            kernel: [kernel[0] as i128, kernel[1] as i128],
            strides: [
                strides.first().copied().unwrap_or(1) as i128,
                strides.get(1).copied().unwrap_or(1) as i128,
            ],
            dilations: [
                dilations.first().copied().unwrap_or(1) as i128,
                dilations.get(1).copied().unwrap_or(1) as i128,
            ],
            begin,
            out,
        })
    }

    /// `Conv` (2-D, NCHW): the data `X`, a constant weight `W` of shape
    /// `[M, C/group, kH, kW]` and an optional constant bias `B` of `M`
    /// entries, as the dense affine map of the flat value (exact: each
    /// entry is a stored weight or zero).
    pub(super) fn conv(&mut self, n: &NodeProto, data_first: bool) -> Result<(), OnnxError> {
        if !data_first {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!("{} convolves a constant by the data", node_label(n)),
                "export with the data as the Conv's first input and constant weights",
            ));
        }
        let wname = n
            .input
            .get(1)
            .filter(|s| !s.is_empty())
            .ok_or_else(|| malformed(n, "has no weight input".to_string()))?;
        let wt = self.named_const(
            n,
            wname,
            "weight",
            "export with constant folding on (weights as initializers)",
        )?;
        let &[m, cg, kh, kw] = wt.dims.as_slice() else {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} has a weight of shape {}; ravel supports 2-D convolutions (a weight [M, C/group, kH, kW])",
                    node_label(n),
                    shape_text(&wt.dims)
                ),
                "export 2-D convolutions on NCHW images",
            ));
        };
        if m == 0 || cg == 0 || kh == 0 || kw == 0 {
            return Err(malformed(
                n,
                format!("has an empty weight of shape {}", shape_text(&wt.dims)),
            ));
        }
        if let Some(k) = ints(n, "kernel_shape", 2)? {
            if k != [kh as i64, kw as i64] {
                return Err(malformed(
                    n,
                    format!(
                        "declares kernel_shape {} but its weight has shape {}",
                        shape_text(&k),
                        shape_text(&wt.dims)
                    ),
                ));
            }
        }
        let group = attr_i(n, "group", 1);
        let [channels, _, _] = self.image(n)?;
        let groups = usize::try_from(group).ok().filter(|g| *g >= 1);
        let Some(groups) = groups.filter(|g| m % g == 0 && cg.checked_mul(*g) == Some(channels))
        else {
            return Err(malformed(
                n,
                format!(
                    "has a weight of shape {} and group {group} on a value of {channels} channels (it needs M divisible by group and C/group = {cg} input channels per group)",
                    shape_text(&wt.dims)
                ),
            ));
        };
        let win = self.window(n, [kh as i64, kw as i64], m)?;
        let bias = match n.input.get(2).filter(|s| !s.is_empty()) {
            Some(bname) => {
                let bt = self.named_const(n, bname, "bias", "biases must be initializers")?;
                if bt.data.len() != m {
                    return Err(malformed(
                        n,
                        format!(
                            "has a bias of shape {} for {m} output channels",
                            shape_text(&bt.dims)
                        ),
                    ));
                }
                bt.data
            }
            None => vec![0.0; m],
        };
        let (plane, cols) = (win.plane(), win.inputs());
        let rows = m * plane;
        self.expect_width(n, cols)?;
        self.reserve(n, rows, cols)?;
        let per_group = m / groups;
        let ([oh, ow], [ih, iw]) = (win.out, win.size);
        let taps_h: Vec<_> = (0..oh).map(|o| win.taps(0, o)).collect();
        let taps_w: Vec<_> = (0..ow).map(|o| win.taps(1, o)).collect();
        // column-major, as nalgebra stores it
        let mut data = vec![0.0; rows * cols];
        for mo in 0..m {
            let g = mo / per_group;
            for (y, th) in taps_h.iter().enumerate() {
                for (x, tw) in taps_w.iter().enumerate() {
                    let row = (mo * oh + y) * ow + x;
                    for c in 0..cg {
                        let ci = g * cg + c;
                        for &(ky, iy) in th {
                            for &(kx, ix) in tw {
                                let wv = wt.data.get(((mo * cg + c) * kh + ky) * kw + kx);
                                let col = (ci * ih + iy) * iw + ix;
                                if let (Some(e), Some(v)) = (data.get_mut(col * rows + row), wv) {
                                    *e = *v;
                                }
                            }
                        }
                    }
                }
            }
        }
        let b = DVector::from_iterator(
            rows,
            bias.iter().flat_map(|v| std::iter::repeat_n(*v, plane)),
        );
        self.push_affine(DMatrix::from_vec(rows, cols, data), b);
        self.shape = Some(vec![1, m, oh, ow]);
        Ok(())
    }

    /// `AveragePool` (`kernel_shape`, `strides`, `pads`/`auto_pad`,
    /// `dilations`, `count_include_pad`; `ceil_mode` 0) and
    /// `GlobalAveragePool`, each output the mean of its window: the sum of
    /// its inputs times the `f64` nearest to `1/k`, where `k` is the
    /// window's size with `count_include_pad` (and for the global mean),
    /// else the number of its taps inside the input.
    pub(super) fn average_pool(&mut self, n: &NodeProto, op: &str) -> Result<(), OnnxError> {
        if n.input.first() != Some(&self.current) {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!("{} averages a constant", node_label(n)),
                "export with constant folding on",
            ));
        }
        let [channels, h, w] = self.image(n)?;
        let (win, include_pad) = if op == "GlobalAveragePool" {
            let win = Window {
                channels,
                size: [h, w],
                kernel: [h as i128, w as i128],
                strides: [1, 1],
                dilations: [1, 1],
                begin: [0, 0],
                out: [1, 1],
            };
            (win, true)
        } else {
            if attr_i(n, "ceil_mode", 0) != 0 {
                return Err(err(
                    OnnxErrorKind::Unsupported,
                    format!("{} has ceil_mode = 1", node_label(n)),
                    "export the pooling with ceil_mode = 0 (PyTorch's default)",
                ));
            }
            let Some(k) = ints(n, "kernel_shape", 2)? else {
                return Err(malformed(n, "has no kernel_shape".to_string()));
            };
            let kernel = [
                k.first().copied().unwrap_or(0),
                k.get(1).copied().unwrap_or(0),
            ];
            let win = self.window(n, kernel, channels)?;
            (win, attr_i(n, "count_include_pad", 0) != 0)
        };
        let (plane, cols) = (win.plane(), win.inputs());
        let rows = channels * plane;
        self.expect_width(n, cols)?;
        self.reserve(n, rows, cols)?;
        let ([oh, ow], [ih, iw]) = (win.out, win.size);
        let taps_h: Vec<_> = (0..oh).map(|o| win.taps(0, o)).collect();
        let taps_w: Vec<_> = (0..ow).map(|o| win.taps(1, o)).collect();
        // the whole window's size (exact in u128: two i64 factors)
        let full = (win.kernel[0] as u128).saturating_mul(win.kernel[1] as u128);
        let mut data = vec![0.0; rows * cols];
        for c in 0..channels {
            for (y, th) in taps_h.iter().enumerate() {
                for (x, tw) in taps_w.iter().enumerate() {
                    let row = (c * oh + y) * ow + x;
                    let k = if include_pad {
                        full
                    } else {
                        (th.len() * tw.len()) as u128
                    };
                    // k ≤ 2⁵³ is an exact f64, and 1/k its nearest
                    if k == 0 || k > 1u128 << 53 {
                        return Err(malformed(
                            n,
                            format!(
                                "averages output ({c}, {y}, {x}) over {k} elements{}",
                                if k == 0 {
                                    " (its window lies in the padding)"
                                } else {
                                    ""
                                }
                            ),
                        ));
                    }
                    let weight = 1.0 / k as f64;
                    for &(_, iy) in th {
                        for &(_, ix) in tw {
                            let col = (c * ih + iy) * iw + ix;
                            if let Some(e) = data.get_mut(col * rows + row) {
                                *e = weight;
                            }
                        }
                    }
                }
            }
        }
        self.push_affine(DMatrix::from_vec(rows, cols, data), DVector::zeros(rows));
        self.shape = Some(vec![1, channels, oh, ow]);
        Ok(())
    }
}
