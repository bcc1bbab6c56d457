"""Coefficient tables of explicit symplectic splitting methods for separable H = T(p) + V(q).

Each table is one step of length h written as alternating exact sub-flows,

    B(b[0]) A(a[0]) B(b[1]) A(a[1]) ... A(a[m-1]) B(b[m]),

applied left to right, where the drift A(c) is q <- q + c h dT/dp(p) (the exact flow of T) and the
kick B(c) is p <- p - c h dV/dq(q) (the exact flow of V). A method published drift-first (ABA...A)
has b[0] = b[m] = 0; a composition of leapfrogs (kick-drift-kick) with weights w_1..w_k has
a = w and b = (w_1/2, (w_1 + w_2)/2, ..., (w_{k-1} + w_k)/2, w_k/2) (`from_leapfrog_weights`).
Coefficients are decimal strings, so that a caller can read them at any precision; every table
here is palindromic (a time-symmetric method) and sums to one in a and in b.

`nystrom` says whether the stated order needs T quadratic in p (a Runge-Kutta-Nyström method:
the order conditions that involve [B, [B, [B, A]]] are then void and are not met). On a general
T(p) those methods are of order 4 only. SABA_n and ABA(10,6,4) are built for a perturbed
H = A + eps B: their `order` is the plain order (eps not small); their orders in eps are in
`reference`.

Where the digits come from is written beside each table. Two kinds needed work: closed forms
and isolated solutions (Yoshida's triple jump and his 6th-order solution A, McLachlan's w_2,
the Gauss-Legendre nodes of SABA_n) were computed here at 70 to 80 digits and agree with the
published digits; Blanes & Moan (2002) print 15 digits, so their free coefficients were moved,
by less than 2e-15, to the nearest point (least change) where the order conditions hold to
1e-60, and are stored to 36 digits.

How the tables were checked (mpmath, not part of the tests): the Taylor expansion in h of one
step, to degree order + 1, against that of the exact flow, on a 2-degree-of-freedom Hamiltonian
built from exponentials (so that no nested bracket vanishes) and on the same with T = |p|^2/2;
every coefficient of degree <= order vanished to 4e-26 (the 26-digit published sets) or better,
the one of degree order + 1 did not. Then the global error at 40 digits, against mpmath's Taylor
integrator, on the pendulum H = p^2/2 - cos q and on H = cosh p + q^4/4 + q^2/2, both from
(q, p) = (1, 0.5) to t = 2: from 32 to 64 steps the slope of log error against log h was `order`
within 0.02 on both, except the Runge-Kutta-Nyström methods on the cosh one, where it was 4.0.
The tests (tests/solutions/test_splitting_tables.py) repeat the slopes at 32 digits, and the
power-sum conditions of the leapfrog compositions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mpmath

from atlasnn.errors import ConfigError

__all__ = ["SplittingScheme", "SCHEMES", "splitting_scheme", "from_leapfrog_weights"]

#: significant digits of the coefficients computed here (the kicks of a leapfrog composition)
_DIGITS = 40


@dataclass(frozen=True)
class SplittingScheme:
    """One step B(b[0]) A(a[0]) B(b[1]) ... A(a[m-1]) B(b[m]); A drifts q, B kicks p.

    Attributes:
        name: the registry key (lower-case).
        order: the order of the step (on any T(p) unless ``nystrom``).
        a: the m drift coefficients, decimal strings.
        b: the m + 1 kick coefficients, decimal strings (an end one is "0" for a drift-first method).
        nystrom: True when ``order`` needs T quadratic in p (Runge-Kutta-Nyström methods).
        reference: where the method was published, and which table or solution it is.
    """

    name: str
    order: int
    a: tuple[str, ...]
    b: tuple[str, ...]
    nystrom: bool
    reference: str

    def __post_init__(self) -> None:
        if not self.a or len(self.b) != len(self.a) + 1:
            raise ConfigError(
                f"splitting scheme {self.name!r}: needs m >= 1 drifts and m + 1 kicks, "
                f"got {len(self.a)} and {len(self.b)}"
            )

    @property
    def a_f(self) -> tuple[float, ...]:
        """The drift coefficients as floats (correctly rounded from the strings)."""
        return tuple(float(c) for c in self.a)

    @property
    def b_f(self) -> tuple[float, ...]:
        """The kick coefficients as floats (correctly rounded from the strings)."""
        return tuple(float(c) for c in self.b)

    @property
    def forces(self) -> int:
        """Force evaluations a step: the nonzero kicks, less one where the step begins and ends with
        a kick (the last force of a step is the first of the next)."""
        b = self.b_f
        return sum(1 for x in b if x != 0.0) - (1 if b[0] != 0.0 and b[-1] != 0.0 else 0)


def _fmt(x: mpmath.mpf, digits: int = _DIGITS) -> str:
    """Fixed-point decimal string of x to `digits` significant digits, no trailing zeros."""
    s = mpmath.nstr(x, digits, min_fixed=-mpmath.inf, max_fixed=mpmath.inf)
    return s[:-2] if s.endswith(".0") else s


def _mirror(half: Sequence[str], centre: bool) -> tuple[str, ...]:
    """The palindrome whose first half is `half` (its last entry is the middle one if `centre`)."""
    tail = half[:-1] if centre else half
    return tuple(half) + tuple(reversed(tail))


def from_leapfrog_weights(name: str, order: int, weights: Sequence[str], reference: str) -> SplittingScheme:
    """The composition of leapfrogs (kick-drift-kick) with the given step weights.

    The drifts are the weights themselves; the kicks, (w_i + w_{i+1}) / 2 between two leapfrogs
    and w_1 / 2, w_k / 2 at the two ends, are computed with mpmath at 40 digits.
    """
    with mpmath.workdps(_DIGITS + 10):
        w = [mpmath.mpf(str(x)) for x in weights]
        kicks = [w[0] / 2] + [(w[i] + w[i + 1]) / 2 for i in range(len(w) - 1)] + [w[-1] / 2]
        b = tuple(_fmt(k) for k in kicks)
    return SplittingScheme(name, order, tuple(str(x) for x in weights), b, False, reference)


def _symmetric_leapfrogs(name: str, order: int, half: Sequence[str], reference: str) -> SplittingScheme:
    """A palindromic composition of leapfrogs, given w_1 .. w_centre."""
    return from_leapfrog_weights(name, order, _mirror(half, centre=True), reference)


def _symmetric(
    name: str, order: int, a_half: Sequence[str], b_half: Sequence[str], nystrom: bool, reference: str
) -> SplittingScheme:
    """A palindromic splitting given the first halves of a and b (with the middle entry, if any).

    Exactly one of a, b has a middle entry: a does when both halves have the same length.
    """
    a_centre = len(a_half) == len(b_half)
    a = _mirror(a_half, centre=a_centre)
    b = _mirror(b_half, centre=not a_centre)
    return SplittingScheme(name, order, a, b, nystrom, reference)


# ---- compositions of leapfrog --------------------------------------------------------------------

_LEAPFROG = from_leapfrog_weights(
    "leapfrog", 2, ("1",),
    "Störmer–Verlet / leapfrog, kick-drift-kick; Verlet (1967), Phys. Rev. 159, 98; "
    "Hairer, Lubich & Wanner (2003), Acta Numerica 12, 399–450",
)

# w_1 = 1/(2 - 2^(1/3)), w_0 = -2^(1/3)/(2 - 2^(1/3)), computed here
_YOSHIDA4 = _symmetric_leapfrogs(
    "yoshida4", 4,
    ("1.351207191959657634047687808971460826922", "-1.702414383919315268095375617942921653844"),
    "Yoshida (1990), Phys. Lett. A 150, 262–268, the 3-stage 'triple jump' "
    "(also Forest & Ruth 1990, Candy & Rozmus 1991, Suzuki 1990)",
)

# Yoshida's solution A (an isolated root of the order conditions), solved here by Newton's method at
# 70 digits from the published digits; it agrees with a 26-digit and a 40-digit public copy to all
# their digits (and with the 21 digits of Principia's tables)
_YOSHIDA6 = _symmetric_leapfrogs(
    "yoshida6", 6,
    ("0.7845136104775572638194976338663498757768", "0.2355732133593581336847931829785346016865",
     "-1.177679984178871006946415680964315734639", "1.315186320683911218884249728238862514352"),
    "Yoshida (1990), Phys. Lett. A 150, 262–268, Table 1, solution A (7 leapfrogs)",
)

# w_1 = 0.28 as McLachlan chose it; w_2 is the root of sum w_i^3 = 0 near 0.6254664284676700450
# (computed here; the 20 digits given by Principia's tables agree), w_3 = 1 - 2 (w_1 + w_2)
_MCLACHLAN4 = _symmetric_leapfrogs(
    "mclachlan4", 4,
    ("0.28", "0.6254664284676700450123389054926490129182", "-0.8109328569353400900246778109852980258364"),
    "McLachlan (1995), SIAM J. Sci. Comput. 16(1), 151–168, the 5-stage order-4 symmetric "
    "composition SS5 (w1 = w5 = 0.28)",
)

# the 26 digits of OrdinaryDiffEq.jl's KahanLi6 / KahanLi8 tableaus (other public copies label them
# s9odr6a and s17odr8a)
_KAHAN_LI6 = _symmetric_leapfrogs(
    "kahan_li6", 6,
    ("0.39216144400731413927925056", "0.33259913678935943859974864", "-0.70624617255763935980996482",
     "0.08221359629355080023149045", "0.79854399093482996339895035"),
    "Kahan & Li (1997), Math. Comp. 66, 1089–1099, s9odr6a (9 leapfrogs)",
)
_KAHAN_LI8 = _symmetric_leapfrogs(
    "kahan_li8", 8,
    ("0.13020248308889008087881763", "0.56116298177510838456196441", "-0.38947496264484728640807860",
     "0.15884190655515560089621075", "-0.39590389413323757733623154", "0.18453964097831570709183254",
     "0.25837438768632204729397911", "0.29501172360931029887096624", "-0.60550853383003451169892108"),
    "Kahan & Li (1997), Math. Comp. 66, 1089–1099, s17odr8a (17 leapfrogs)",
)

# the 26 digits of OrdinaryDiffEq.jl (SofSpa10 tableau)
_SOFSPA10 = _symmetric_leapfrogs(
    "sofspa10", 10,
    ("0.07879572252168641926390768", "0.31309610341510852776481247", "0.02791838323507806610952027",
     "-0.22959284159390709415121340", "0.13096206107716486317465686", "-0.26973340565451071434460973",
     "0.07497334315589143566613711", "0.11199342399981020488957508", "0.36613344954622675119314812",
     "-0.39910563013603589787862981", "0.10308739852747107731580277", "0.41143087395589023782070412",
     "-0.00486636058313526176219566", "-0.39203335370863990644808194", "0.05194250296244964703718290",
     "0.05066509075992449633587434", "0.04967437063972987905456880", "0.04931773575959453791768001"),
    "Sofroniou & Spaletta (2005), Optim. Methods Softw. 20, 597–613, s = 35, order 10",
)

# ---- Blanes & Moan (2002) -------------------------------------------------------------------------
# Printed to 15 digits; the free coefficients were moved to the nearest exact solution of the order
# conditions (by at most 1.4e-15; least change, mpmath) and are kept to 36 digits.

_BM_REF = "Blanes & Moan (2002), J. Comput. Appl. Math. 142, 313–330"
_BM_NOTE = " (15 printed digits completed to 36 on the order conditions)"

_BLANES_MOAN4 = _symmetric(
    "blanes_moan4", 4,
    ("0.0792036964311956694336634958882688733", "0.353172906049773988481061311573121057",
     "-0.0420650803577195353681102983025170387", "0.219376955753499754906770981682254218"),
    ("0", "0.209515106613362021274072640029501017", "-0.143851773179818008275115057856527726",
     "0.434336666566455987001042417827026709"),
    False, _BM_REF + ", PRK method S6 (drift first, 6 kicks)" + _BM_NOTE,
)
_BLANES_MOAN6 = _symmetric(
    "blanes_moan6", 6,
    ("0.0502627644003926860212216544020741094", "0.413514300428343815063063720133884439",
     "0.0450798897943980629688970521245134712", "-0.188054853819568914799128488918870542",
     "0.541960678450780134831414740933072496", "-0.725525558508691568170937357349347947"),
    ("0", "0.148816447901043231920901005535577589", "-0.132385865767783647448845426598939922",
     "0.0673076046921844581502578965926010469", "0.432666402578173597527667970883545298",
     "-0.0164045894036176401499814464127840123"),
    False, _BM_REF + ", PRK method S10 (drift first, 10 kicks)" + _BM_NOTE,
)
# SRKN_6^b: order 4 holds for any T(p) as well (a symmetric method has no conditions of even
# degree, and the one RKN-only bracket below degree 5 is of degree 4), hence nystrom=False
_BLANES_MOAN_RKN4 = _symmetric(
    "blanes_moan_rkn4", 4,
    ("0.24529895718427116260393242600140088", "0.604872665711079974960892697643076245",
     "-0.350171622895351137564825123644477126"),
    ("0.0829844064174050188383474789422501125", "0.396309801498368077094911528263686739",
     "-0.0390563049223484351708652907653792423", "0.119524194013150678475212567118884781"),
    False, _BM_REF + ", RKN method SRKN_6^b (kick first); optimised for quadratic T" + _BM_NOTE,
)
_BLANES_MOAN_RKN6 = _symmetric(
    "blanes_moan_rkn6", 6,
    ("0.123229775946271151561086380333366753", "0.290553797799558270366414169327916183",
     "-0.127049212625416915662505053827485934", "-0.246331761062075404194973489104062863",
     "0.357208872795927752619860349619310463", "0.204777054291470290620235287301910797"),
    ("0.0414649985182628432987781339147049367", "0.198128671918066541136726473181496961",
     "-0.0400061921041526868888283635359448394", "0.0752539843015803411278788785270427555",
     "-0.0115113874206877700624432015012891996", "0.236669924786930731387888079413989386"),
    True, _BM_REF + ", RKN method SRKN_11^b (kick first); order 4 on a general T" + _BM_NOTE,
)

# ---- Blanes, Casas & Escorihuela-Tomàs (2022), order 8 RKN ------------------------------------------
# 30 digits from a public port of the paper's 17-evaluation BAB method; the two middle entries are
# 1 - 2 sum and 1/2 - sum of the others. The port used these 18 values as drifts, which gives order 4;
# as kicks (kick first) they meet every RKN condition up to order 8 to 1e-31.
_BCE_RKN8 = _symmetric(
    "bce_rkn8", 8,
    ("0.160227696073839513690970240076", "0.306354507436867319879440957100",
     "0.308395508895171191756544975556", "0.120362086566233408450063177659",
     "-0.622888687549183872072186218718", "0.635560951632990078378672016548",
     "-0.144226974795419229640437363913", "-0.284867527074173816678992817545",
     "0.042164877627350812471850066474"),
    ("0.0514196142537210073343152693459", "0.250497030318342871458417941091",
     "0.512412268300327350035492806653", "-0.231597138650894401279645184364",
     "0.116091323536875759881216298975", "-0.0098365173246965763985763034283",
     "-0.108032771466281638634277563747", "0.249039864198023642002940910070",
     "-0.3299936731654180143998841745956"),
    True,
    "Blanes, Casas & Escorihuela-Tomàs (2022), 'Runge–Kutta–Nyström symplectic splitting methods "
    "of order 8', arXiv:2202.01541, the 17-evaluation BAB method (kick first, FSAL); "
    "order 4 on a general T",
)

# ---- methods for perturbed H = A + eps B (A: the drift T here) ------------------------------------
# SABA_n: the drifts step between the n Gauss-Legendre nodes of (0, 1), the kicks are their weights
# (computed here at 80 digits; the same as REBOUND's 40-digit tables)
_SABA_REF = (
    "Laskar & Robutel (2001), Celest. Mech. Dyn. Astron. 80, 39–62, SABA_{n}; for H = A + eps B, "
    "error O(eps h^{p} + eps^2 h^2): order 2 when eps is not small"
)
_SABA2 = _symmetric(
    "saba2", 2,
    ("0.2113248654051871177454256097490212721762", "0.5773502691896257645091487805019574556476"),
    ("0", "0.5"),
    False, _SABA_REF.format(n=2, p=4),
)
_SABA3 = _symmetric(
    "saba3", 2,
    ("0.1127016653792583114820734600217600389167", "0.3872983346207416885179265399782399610833"),
    ("0", "0.2777777777777777777777777777777777777778", "0.4444444444444444444444444444444444444444"),
    False, _SABA_REF.format(n=3, p=6),
)
_SABA4 = _symmetric(
    "saba4", 2,
    ("0.06943184420297371238802675555359524745214", "0.2605776340045981552106403648947824089476",
     "0.3399810435848562648026657591032446872006"),
    ("0", "0.1739274225687269286865319746109997036177", "0.3260725774312730713134680253890002963823"),
    False, _SABA_REF.format(n=4, p=8),
)
# ABA(10,6,4): the 40 digits of REBOUND's integrator_saba.c; its conditions hold to 1e-41
_ABA1064 = _symmetric(
    "aba1064", 4,
    ("0.03809449742241219545697532230863756534060", "0.1452987161169137492940200726606637497442",
     "0.2076276957255412507162056113249882065158", "0.4359097036515261592231548624010651844006",
     "-0.6538612258327867093807117373907094120024"),
    ("0", "0.09585888083707521061077150377145884776921", "0.2044461531429987806805077839164344779763",
     "0.2170703479789911017143385924306336714532", "-0.01737538195906509300561788011852699719871"),
    False,
    "Blanes, Casas, Farrés, Laskar, Makazaga & Murua (2013), Appl. Numer. Math. 68, "
    "ABA(10,6,4) (drift first, 8 kicks); for H = A + eps B, error O(eps h^10 + eps^2 h^6 + eps^3 h^4)",
)

#: every scheme by name, in order of increasing order
SCHEMES: dict[str, SplittingScheme] = {
    s.name: s
    for s in (
        _LEAPFROG, _SABA2, _SABA3, _SABA4,
        _YOSHIDA4, _MCLACHLAN4, _BLANES_MOAN4, _BLANES_MOAN_RKN4, _ABA1064,
        _YOSHIDA6, _KAHAN_LI6, _BLANES_MOAN6, _BLANES_MOAN_RKN6,
        _KAHAN_LI8, _BCE_RKN8,
        _SOFSPA10,
    )
}


def splitting_scheme(name: str) -> SplittingScheme:
    """The scheme registered under `name`; ConfigError if there is none."""
    try:
        return SCHEMES[name]
    except KeyError:
        raise ConfigError(f"unknown splitting scheme {name!r}; choose one of [{', '.join(SCHEMES)}]") from None
