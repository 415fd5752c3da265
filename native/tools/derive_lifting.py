"""Derives the lifting steps of the long Daubechies wavelets (D12 = db6, D20 = db10).

Daubechies & Sweldens (1998), "Factoring wavelet transforms into lifting
steps". D12: the analysis polyphase matrix A(z) of PyWavelets' db6 pair is
reduced to a diagonal (scaling) matrix by column operations, each one a
lifting step, chosen by a Euclidean algorithm on the first row (in 40-digit
arithmetic, quotients picked for small coefficients). D20: that route needs
coefficients up to 68 for db10, too many for float32, so db10 uses the
paraunitary lattice instead (derive_lattice). The result is printed as C++
initialisers for native/src/gradient/wavelet_filters.cpp and checked here in float64
against the filter taps.

Conventions (those of native/src/gradient/wavelet_lifting.cpp): a Laurent polynomial
{offset: c} applied to a sequence y gives sum_k c_k y[n + k]. The signal x is
split into even xe[n] = x[2n] and odd xo[n] = x[2n + 1]; an "update" step does
s[n] += sum_k c_k d[n + k], a "predict" step d[n] += sum_k c_k s[n + k];
the last step is followed by s *= scale_s, d *= scale_d.

Run:  /usr/bin/python3 native/tools/derive_lifting.py
"""
import itertools
import sys

import mpmath
import numpy as np
import pywt

# The Euclidean algorithm loses digits on long filters; 40 digits keep the
# float64 result exact to the last bit.
mpmath.mp.dps = 40
ZERO = mpmath.mpf("1e-9")  # below this a coefficient is round-off of the float64 taps


class Laurent:
    """sum_k c[k - lo] z^k with float64 coefficients."""

    def __init__(self, lo, coeffs):
        c = np.array([mpmath.mpf(v) for v in coeffs], dtype=object)
        nz = np.nonzero(np.array([abs(v) > ZERO for v in c], dtype=bool))[0]
        if len(nz) == 0:
            self.lo, self.c = 0, np.zeros(0, dtype=object)
        else:
            self.lo, self.c = lo + nz[0], c[nz[0]:nz[-1] + 1]

    @property
    def hi(self):
        return self.lo + len(self.c) - 1

    def is_zero(self):
        return len(self.c) == 0

    def __mul__(self, o):
        if self.is_zero() or o.is_zero():
            return Laurent(0, [])
        return Laurent(self.lo + o.lo, np.convolve(self.c, o.c))

    def __add__(self, o):
        if self.is_zero():
            return o
        if o.is_zero():
            return self
        lo, hi = min(self.lo, o.lo), max(self.hi, o.hi)
        c = np.array([mpmath.mpf(0)] * (hi - lo + 1), dtype=object)
        c[self.lo - lo:self.hi - lo + 1] += self.c
        c[o.lo - lo:o.hi - lo + 1] += o.c
        return Laurent(lo, c)

    def __neg__(self):
        return Laurent(self.lo, -self.c)

    def __sub__(self, o):
        return self + (-o)

    def terms(self):
        return {self.lo + i: float(v) for i, v in enumerate(self.c)}


def polyphase(taps, offset):
    """Filter f with s[n] = sum_k f[k] x[2n + k + offset] -> (F_even, F_odd)."""
    even, odd = {}, {}
    for k, v in enumerate(taps):
        m = k + offset
        (even if m % 2 == 0 else odd)[m // 2] = v
    def lp(d):
        lo = min(d)
        return Laurent(lo, [d.get(i, 0.0) for i in range(lo, max(d) + 1)])
    return lp(even), lp(odd)


def divide(a, b):
    """All quotients q making a - q b shorter than b; returns the one with
    the smallest largest coefficient (keeps float32 round-off small)."""
    na, nb = len(a.c), len(b.c)
    best = None
    # q*b spans exactly a's powers [a.lo, a.hi]: q has na - nb + 1 terms.
    qpowers = list(range(a.lo - b.lo, a.hi - b.hi + 1))
    for t in range(na - nb + 2):
        # The remainder lives on powers [a.lo + t, a.lo + t + nb - 2]; every
        # other power of a is cancelled.
        window = set(range(a.lo + t, a.lo + t + nb - 1))
        kill = [p for p in range(a.lo, a.hi + 1) if p not in window]
        if len(qpowers) != len(kill):
            continue
        M = mpmath.matrix(len(kill), len(qpowers))
        for j, qp in enumerate(qpowers):
            for i, p in enumerate(kill):
                k = p - qp - b.lo
                if 0 <= k < nb:
                    M[i, j] = b.c[k]
        rhs = mpmath.matrix([a.c[p - a.lo] for p in kill])
        try:
            qc = list(mpmath.lu_solve(M, rhs))
        except ZeroDivisionError:
            continue
        q = Laurent(qpowers[0], qc)
        r = a - q * b
        if not r.is_zero() and len(r.c) >= nb:
            continue
        score = max(abs(v) for v in qc)
        if best is None or score < best[0]:
            best = (score, q, r)
    assert best is not None, "no quotient"
    return best[1], best[2]


def factor(h, g, h_offset, g_offset, ties=0):
    He, Ho = polyphase(h, h_offset)
    Ge, Go = polyphase(g, g_offset)
    A = [[He, Ho], [Ge, Go]]
    steps = []  # (kind, Laurent) in the order the forward transform applies them
    # Column operations on A: the first lifting step applied to (xe, xo) is
    # peeled off A's right side.  update  U: col1 -= U col0  (xe += U xo)
    #                               predict P: col0 -= P col1  (xo += P xe)
    tie = 0
    while not (A[0][0].is_zero() or A[0][1].is_zero()):
        n0, n1 = len(A[0][0].c), len(A[0][1].c)
        reduce_odd = n1 > n0
        if n1 == n0:  # either column may be reduced: `ties` picks, bit by bit
            reduce_odd = not (ties >> tie) & 1
            tie += 1
        if reduce_odd:
            q, _ = divide(A[0][1], A[0][0])
            A[0][1] = A[0][1] - q * A[0][0]
            A[1][1] = A[1][1] - q * A[1][0]
            steps.append(("update", q))
        else:
            q, _ = divide(A[0][0], A[0][1])
            A[0][0] = A[0][0] - q * A[0][1]
            A[1][0] = A[1][0] - q * A[1][1]
            steps.append(("predict", q))
    if A[0][0].is_zero():
        # First row (0, K z^c): predict -1 moves it to column 0, update 1 clears column 1.
        minus_one, one = Laurent(0, [-1.0]), Laurent(0, [1.0])
        A[0][0] = A[0][0] - minus_one * A[0][1]
        A[1][0] = A[1][0] - minus_one * A[1][1]
        steps.append(("predict", minus_one))
        A[0][1] = A[0][1] - one * A[0][0]
        A[1][1] = A[1][1] - one * A[1][0]
        steps.append(("update", one))
    assert len(A[0][0].c) == 1 and len(A[1][1].c) == 1, "det is not a monomial"
    # Kill A[1][0] with a last predict step: col0 -= P col1.
    P = Laurent(A[1][0].lo - A[1][1].lo, A[1][0].c / A[1][1].c[0])
    if not P.is_zero():
        A[1][0] = A[1][0] - P * A[1][1]
        steps.append(("predict", P))
    assert A[1][0].is_zero() and A[0][1].is_zero()
    shift_s, shift_d = A[0][0].lo, A[1][1].lo
    return steps, A[0][0].c[0], A[1][1].c[0], shift_s, shift_d


def merge(steps):
    out = []
    for kind, q in steps:
        if out and out[-1][0] == kind:
            out[-1] = (kind, out[-1][1] + q)
        else:
            out.append((kind, q))
    return out


def lift_forward(x, steps, ks, kd):
    """float64 periodic reference of the C++ lifting loop."""
    s, d = x[0::2].copy(), x[1::2].copy()
    m = len(s)
    for kind, q in steps:
        src, dst = (d, s) if kind == "update" else (s, d)
        acc = np.zeros(m)
        for k, c in q.terms().items():
            acc += float(c) * np.roll(src, -k)
        dst += acc
    return s * float(ks), d * float(kd)


def derive(name, pywt_name):
    w = pywt.Wavelet(pywt_name)
    h = [mpmath.mpf(v) for v in w.rec_lo]
    g = [mpmath.mpf(v) for v in w.rec_hi]
    L = len(h)
    best = None
    TIES = 64
    for g_off, ties in itertools.product(range(-L, L + 1, 2), range(TIES)):
        try:
            steps, ks, kd, ss, sd = factor(h, g, 0, g_off, ties)
        except (AssertionError, RuntimeError):
            continue
        steps = merge(steps)
        biggest = float(max(max(abs(v) for v in q.c) for _, q in steps))
        if best is None or biggest < best[0]:
            best = (biggest, g_off, steps, ks, kd, ss, sd)
    biggest, g_off, steps, ks, kd, ss, sd = best
    # Check: the lifting equals the filters, up to the shifts found.
    rng = np.random.default_rng(0)
    x = rng.standard_normal(64)
    s, d = lift_forward(x, steps, ks, kd)
    n = np.arange(32)
    hf, gf = [float(v) for v in h], [float(v) for v in g]
    ref_s = np.array([sum(hf[k] * x[(2 * i + k) % 64] for k in range(L)) for i in n])
    ref_d = np.array([sum(gf[k] * x[(2 * i + k + g_off) % 64] for k in range(L)) for i in n])
    err_s = np.max(np.abs(np.roll(s, -ss) - ref_s))
    err_d = np.max(np.abs(np.roll(d, -sd) - ref_d))
    print(f"// {name} ({pywt_name}): {len(steps)} steps, largest coefficient {biggest:.3g}, "
          f"g offset {g_off}, shifts s {ss} d {sd}, check error {max(err_s, err_d):.2e}", file=sys.stderr)
    assert max(err_s, err_d) < 1e-8
    return steps, ks, kd


def emit(name, steps, ks, kd):
    print(f"// {name}: derived by native/tools/derive_lifting.py")
    for i, (kind, q) in enumerate(steps):
        coeffs = ", ".join(f"{float(v):.17g}" for v in q.c)
        print(f"constexpr double k{name}Step{i}[] = {{{coeffs}}};")
    print(f"const LiftingStep k{name}Steps[] = {{")
    for i, (kind, q) in enumerate(steps):
        print(f"    {{LiftingStep::{'Update' if kind == 'update' else 'Predict'}, {q.lo}, "
              f"{len(q.c)}, k{name}Step{i}}},")
    print("};")
    print(f"constexpr double k{name}ScaleS = {float(ks):.17g};")
    print(f"constexpr double k{name}ScaleD = {float(kd):.17g};")


def derive_lattice(name, pywt_name):
    """Paraunitary lattice factorization (Vaidyanathan; Daubechies & Sweldens
    1998, sec. 7): A(z) = A0 * prod(diag(1, z) R_k^T), every R_k a rotation,
    itself three lifting steps with coefficients tan(theta/2), sin(theta)
    (|.| <= 1 for |theta| <= pi/2). The Euclidean factorization of db10 needs
    coefficients up to 68, which float32 cannot carry through a perfect
    reconstruction; this one stays at most 1."""
    w = pywt.Wavelet(pywt_name)
    h = np.array(w.rec_lo, dtype=np.float64)
    g = np.array(w.rec_hi, dtype=np.float64)
    L = len(h)
    K = L // 2
    # Polyphase coefficient matrices A[p] (2x2) of z^p, p = 0..K-1: row 0
    # the low-pass h, row 1 the high-pass g, both reading x[2n .. 2n + L).
    A = np.zeros((K, 2, 2))
    for k in range(L):
        A[k // 2, 0, k % 2] = h[k]
        A[k // 2, 1, k % 2] = g[k]
    # A(z) = sum_p A[p] z^p must be paraunitary: sum_p A[p] A[p]^T = I.
    assert np.allclose(sum(A[p] @ A[p].T for p in range(K)), np.eye(2)), "not paraunitary"
    rotations = []  # forward order
    while len(A) > 1:
        top = A[-1]
        # Rows of the top coefficient are multiples of v; rotate so that
        # column 0 loses the top power and column 1 the bottom one.
        v = top[np.argmax(np.linalg.norm(top, axis=1))]
        v = v / np.linalg.norm(v)
        t = np.array([v[1], -v[0]])
        R = np.column_stack([t, v])
        if np.linalg.det(R) < 0:
            R = np.column_stack([-t, v])
        if R[0, 0] < 0:  # keep the angle within (-pi/2, pi/2]: R -> -R
            R = -R
        B = np.einsum("pij,jk->pik", A, R)
        assert np.allclose(B[-1][:, 0], 0, atol=1e-12) and np.allclose(B[0][:, 1], 0, atol=1e-12)
        C = np.zeros((len(A) - 1, 2, 2))
        C[:, :, 0] = B[:-1, :, 0]
        C[:, :, 1] = B[1:, :, 1]  # C col1 = z^-1 B col1
        rotations.append(R.T)  # applied first, then the odd band advances by one
        A = C
    final = A[0]
    sign_d = 1.0
    if np.linalg.det(final) < 0:
        final = np.diag([1.0, -1.0]) @ final
        sign_d = -1.0
    rotations.append(final)
    # Each rotation [[c, s], [-s, c]] = U(a) P(-s) U(a), a = (1 - c) / s,
    # applied right to left: update a, predict -s, update a. The k-th
    # rotation comes after k advances of the odd band, which shift the
    # offsets at which the stored d is read (update) or written (predict).
    steps = []
    delay = 0
    for k, Rt in enumerate(rotations):
        c, s_ = Rt[0, 0], Rt[0, 1]
        assert np.isclose(Rt[1, 0], -s_) and np.isclose(Rt[1, 1], c) and c > 0
        if abs(s_) > 1e-15:
            a = (1.0 - c) / s_
            steps.append(("update", Laurent(delay, [a])))
            steps.append(("predict", Laurent(-delay, [-s_])))
            steps.append(("update", Laurent(delay, [a])))
        if k < len(rotations) - 1:
            delay += 1
    steps = merge(steps)
    biggest = max(float(np.max(np.abs(q.c.astype(float)))) for _, q in steps)
    # Check against the taps (periodic): the stored d[n + delay] is the detail at n.
    rng = np.random.default_rng(0)
    x = rng.standard_normal(64)
    s, d = lift_forward(x, steps, 1.0, sign_d)
    n = np.arange(32)
    ref_s = np.array([sum(h[k] * x[(2 * i + k) % 64] for k in range(L)) for i in n])
    ref_d = np.array([sum(g[k] * x[(2 * i + k) % 64] for k in range(L)) for i in n])
    err = max(np.max(np.abs(s - ref_s)), np.max(np.abs(np.roll(d, -delay) - ref_d)))
    print(f"// {name} ({pywt_name}) lattice: {len(steps)} steps, largest coefficient {biggest:.3g}, "
          f"detail delay {delay}, check error {err:.2e}", file=sys.stderr)
    assert err < 1e-11
    return steps, 1.0, sign_d


if __name__ == "__main__":
    emit("D12", *derive("D12", "db6"))
    emit("D20", *derive_lattice("D20", "db10"))
