// The lifting factorizations of every wavelet, and their names.
#include <cmath>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/gradient/wavelet.h"

namespace lmrefine {
namespace {

const double kSqrt2 = std::sqrt(2.0);
const double kSqrt3 = std::sqrt(3.0);

// Haar: d = xo - xe, s = xe + d/2 = (xe + xo)/2, scaled to the orthonormal
// pair; the detail's sign follows PyWavelets: d = (x[2n] - x[2n+1])/sqrt2.
constexpr double kHaarPredict[] = {-1.0};
constexpr double kHaarUpdate[] = {0.5};
const LiftingStep kHaarSteps[] = {
    {LiftingStep::Predict, 0, 1, kHaarPredict},
    {LiftingStep::Update, 0, 1, kHaarUpdate},
};

// D4 exactly as docs/method.md §3: update 1, predict, update 2, normalize.
const double kD4Update1[] = {kSqrt3};
const double kD4Predict[] = {-(kSqrt3 - 2.0) / 4.0, -kSqrt3 / 4.0};  // s[n-1], s[n]
constexpr double kD4Update2[] = {-1.0};                              // d[n+1]
const LiftingStep kD4Steps[] = {
    {LiftingStep::Update, 0, 1, kD4Update1},
    {LiftingStep::Predict, -1, 2, kD4Predict},
    {LiftingStep::Update, 1, 1, kD4Update2},
};

// D12 (db6) and D20 (db10), from PyWavelets' taps, computed once by
// native/tools/derive_lifting.py (which checks them against the taps).
// D12: Euclidean factorization of the polyphase matrix, quotients chosen to
// keep the coefficients small (at most 0.73). D20: the Euclidean route needs
// coefficients up to 68 and loses float32 perfect reconstruction, so it is
// the paraunitary lattice (one rotation = three lifting steps per stage,
// coefficients at most 1); its stored detail is the db10 detail 9 samples on.
// D12: derived by native/tools/derive_lifting.py
constexpr double kD12Step0[] = {0.22550617856378882};
constexpr double kD12Step1[] = {0.72734207409723428, -0.2145934500030082};
constexpr double kD12Step2[] = {-0.39111354797562786, -0.50700556856554502};
constexpr double kD12Step3[] = {0.6595714136346803, -0.27184625934453871};
constexpr double kD12Step4[] = {-0.059086371510430682, 0.20512679659261041};
constexpr double kD12Step5[] = {0.08252478647755461, -0.011386511463891989};
constexpr double kD12Step6[] = {0.0081917356161318143};
const LiftingStep kD12Steps[] = {
    {LiftingStep::Predict, 0, 1, kD12Step0},
    {LiftingStep::Update, -1, 2, kD12Step1},
    {LiftingStep::Predict, 0, 2, kD12Step2},
    {LiftingStep::Update, 0, 2, kD12Step3},
    {LiftingStep::Predict, -2, 2, kD12Step4},
    {LiftingStep::Update, 2, 2, kD12Step5},
    {LiftingStep::Predict, -3, 1, kD12Step6},
};
constexpr double kD12ScaleS = 0.92095027555795639;
constexpr double kD12ScaleD = -1.0858349538949326;
// D20: derived by native/tools/derive_lifting.py
constexpr double kD20Step0[] = {0.86826485514921803};
constexpr double kD20Step1[] = {-0.99010530355080328};
constexpr double kD20Step2[] = {0.86826485514921803, -0.64847705562223756};
constexpr double kD20Step3[] = {0.91301202117618485};
constexpr double kD20Step4[] = {-0.64847705562223756, 0.46995075796645469};
constexpr double kD20Step5[] = {-0.76987234789198278};
constexpr double kD20Step6[] = {0.46995075796645469, -0.32155063896617347};
constexpr double kD20Step7[] = {0.58283877186199384};
constexpr double kD20Step8[] = {-0.32155063896617347, 0.19977204617283387};
constexpr double kD20Step9[] = {-0.38421067817188376};
constexpr double kD20Step10[] = {0.19977204617283387, -0.10663434200015261};
constexpr double kD20Step11[] = {0.21087089573914372};
constexpr double kD20Step12[] = {-0.10663434200015261, 0.045422356353679749};
constexpr double kD20Step13[] = {-0.09065766867053178};
constexpr double kD20Step14[] = {0.045422356353679749, -0.014030340822148135};
constexpr double kD20Step15[] = {0.028055158973244211};
constexpr double kD20Step16[] = {-0.014030340822148135, 0.002732138035848616};
constexpr double kD20Step17[] = {-0.0054642352834480936};
constexpr double kD20Step18[] = {0.002732138035848616, -0.00024867216516374056};
constexpr double kD20Step19[] = {0.0004973442991207588};
constexpr double kD20Step20[] = {-0.00024867216516374056};
const LiftingStep kD20Steps[] = {
    {LiftingStep::Update, 0, 1, kD20Step0},
    {LiftingStep::Predict, 0, 1, kD20Step1},
    {LiftingStep::Update, 0, 2, kD20Step2},
    {LiftingStep::Predict, -1, 1, kD20Step3},
    {LiftingStep::Update, 1, 2, kD20Step4},
    {LiftingStep::Predict, -2, 1, kD20Step5},
    {LiftingStep::Update, 2, 2, kD20Step6},
    {LiftingStep::Predict, -3, 1, kD20Step7},
    {LiftingStep::Update, 3, 2, kD20Step8},
    {LiftingStep::Predict, -4, 1, kD20Step9},
    {LiftingStep::Update, 4, 2, kD20Step10},
    {LiftingStep::Predict, -5, 1, kD20Step11},
    {LiftingStep::Update, 5, 2, kD20Step12},
    {LiftingStep::Predict, -6, 1, kD20Step13},
    {LiftingStep::Update, 6, 2, kD20Step14},
    {LiftingStep::Predict, -7, 1, kD20Step15},
    {LiftingStep::Update, 7, 2, kD20Step16},
    {LiftingStep::Predict, -8, 1, kD20Step17},
    {LiftingStep::Update, 8, 2, kD20Step18},
    {LiftingStep::Predict, -9, 1, kD20Step19},
    {LiftingStep::Update, 9, 1, kD20Step20},
};
constexpr double kD20ScaleS = 1;
constexpr double kD20ScaleD = -1;

// CDF 5/3 (LeGall): linear predict, then an update keeping the mean.
constexpr double kCdf53Predict[] = {-0.5, -0.5};  // s[n], s[n+1]
constexpr double kCdf53Update[] = {0.25, 0.25};   // d[n-1], d[n]
const LiftingStep kCdf53Steps[] = {
    {LiftingStep::Predict, 0, 2, kCdf53Predict},
    {LiftingStep::Update, -1, 2, kCdf53Update},
};

// CDF 9/7 (Daubechies & Sweldens 1998, as in JPEG 2000).
constexpr double kCdf97Alpha[] = {-1.586134342059924, -1.586134342059924};
constexpr double kCdf97Beta[] = {-0.052980118572961, -0.052980118572961};
constexpr double kCdf97Gamma[] = {0.882911075530934, 0.882911075530934};
constexpr double kCdf97Delta[] = {0.443506852043971, 0.443506852043971};
constexpr double kCdf97K = 1.230174104914001;  // the low-pass gain at DC after the four steps
const LiftingStep kCdf97Steps[] = {
    {LiftingStep::Predict, 0, 2, kCdf97Alpha},
    {LiftingStep::Update, -1, 2, kCdf97Beta},
    {LiftingStep::Predict, 0, 2, kCdf97Gamma},
    {LiftingStep::Update, -1, 2, kCdf97Delta},
};

template <size_t N>
constexpr int count_of(const LiftingStep (&)[N]) {
    return int(N);
}

}  // namespace

const LiftingScheme& lifting_scheme(Wavelet wavelet) {
    // Scales give every scheme a low-pass DC gain of sqrt2 (orthonormal for
    // the orthogonal wavelets, as PyWavelets normalizes them) and |det| 1.
    // Haar, cdf53 and cdf97 then equal PyWavelets' haar, bior2.2 and bior4.4
    // (mode='periodization') exactly, the detail's sign included; the D4
    // detail keeps the sign of docs/method.md §3 (docs/wavelets.md has the relations).
    static const LiftingScheme haar{kHaarSteps, count_of(kHaarSteps), kSqrt2, -1.0 / kSqrt2};
    static const LiftingScheme d4{kD4Steps, count_of(kD4Steps), (kSqrt3 - 1.0) / kSqrt2, (kSqrt3 + 1.0) / kSqrt2};
    static const LiftingScheme d12{kD12Steps, count_of(kD12Steps), kD12ScaleS, kD12ScaleD};
    static const LiftingScheme d20{kD20Steps, count_of(kD20Steps), kD20ScaleS, kD20ScaleD};
    static const LiftingScheme cdf53{kCdf53Steps, count_of(kCdf53Steps), kSqrt2, -1.0 / kSqrt2};
    static const LiftingScheme cdf97{kCdf97Steps, count_of(kCdf97Steps), kSqrt2 / kCdf97K, -kCdf97K / kSqrt2};
    switch (wavelet) {
        case Wavelet::Haar: return haar;
        case Wavelet::D4: return d4;
        case Wavelet::D12: return d12;
        case Wavelet::D20: return d20;
        case Wavelet::Cdf53: return cdf53;
        case Wavelet::Cdf97: return cdf97;
    }
    LMREFINE_THROW(InvalidArgument, "unknown wavelet");
}

const char* valid_wavelet_names() { return "'haar', 'd4', 'd12', 'd20', 'cdf53', 'cdf97'"; }

const char* wavelet_name(Wavelet wavelet) {
    switch (wavelet) {
        case Wavelet::Haar: return "haar";
        case Wavelet::D4: return "d4";
        case Wavelet::D12: return "d12";
        case Wavelet::D20: return "d20";
        case Wavelet::Cdf53: return "cdf53";
        case Wavelet::Cdf97: return "cdf97";
    }
    return "?";
}

Wavelet parse_wavelet(const std::string& name) {
    for (Wavelet w : {Wavelet::Haar, Wavelet::D4, Wavelet::D12, Wavelet::D20, Wavelet::Cdf53, Wavelet::Cdf97}) {
        if (name == wavelet_name(w)) return w;
    }
    LMREFINE_THROW(InvalidArgument, "unknown wavelet '" + name + "'; valid names: " + valid_wavelet_names());
}

BoundaryMode parse_boundary_mode(const std::string& name) {
    if (name == "periodic") return BoundaryMode::Periodic;
    if (name == "symmetric") return BoundaryMode::Symmetric;
    LMREFINE_THROW(InvalidArgument, "unknown boundary mode '" + name + "'; valid modes: 'periodic', 'symmetric'");
}

}  // namespace lmrefine
