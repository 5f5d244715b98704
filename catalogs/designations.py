"""Normalise star names and Bayer/Flamsteed designations into lookup keys.

Every spelling a user may type for one star maps to the same key:
"Alpha Lyrae", "alf Lyr", "α Lyr", "ALPHA LYR", "alpha-lyr" -> "alflyr";
"pi2 Ori", "π² Ori", "pi.02 Ori" -> "pi2ori"; "Rigil Kentaurus" -> "rigilkentaurus".
"""

from __future__ import annotations

import re
import unicodedata

# Greek letter: (abbreviation used by the BSC/SIMBAD, full name, Unicode letter).
GREEK_LETTERS = (
    ("alf", "alpha", "α"), ("bet", "beta", "β"), ("gam", "gamma", "γ"),
    ("del", "delta", "δ"), ("eps", "epsilon", "ε"), ("zet", "zeta", "ζ"),
    ("eta", "eta", "η"), ("tet", "theta", "θ"), ("iot", "iota", "ι"),
    ("kap", "kappa", "κ"), ("lam", "lambda", "λ"), ("mu", "mu", "μ"),
    ("nu", "nu", "ν"), ("ksi", "xi", "ξ"), ("omi", "omicron", "ο"),
    ("pi", "pi", "π"), ("rho", "rho", "ρ"), ("sig", "sigma", "σ"),
    ("tau", "tau", "τ"), ("ups", "upsilon", "υ"), ("phi", "phi", "φ"),
    ("chi", "chi", "χ"), ("psi", "psi", "ψ"), ("ome", "omega", "ω"),
)

# IAU constellation: (abbreviation, name, genitive).
CONSTELLATIONS = (
    ("And", "Andromeda", "Andromedae"), ("Ant", "Antlia", "Antliae"),
    ("Aps", "Apus", "Apodis"), ("Aqr", "Aquarius", "Aquarii"),
    ("Aql", "Aquila", "Aquilae"), ("Ara", "Ara", "Arae"),
    ("Ari", "Aries", "Arietis"), ("Aur", "Auriga", "Aurigae"),
    ("Boo", "Bootes", "Bootis"), ("Cae", "Caelum", "Caeli"),
    ("Cam", "Camelopardalis", "Camelopardalis"), ("Cnc", "Cancer", "Cancri"),
    ("CVn", "Canes Venatici", "Canum Venaticorum"), ("CMa", "Canis Major", "Canis Majoris"),
    ("CMi", "Canis Minor", "Canis Minoris"), ("Cap", "Capricornus", "Capricorni"),
    ("Car", "Carina", "Carinae"), ("Cas", "Cassiopeia", "Cassiopeiae"),
    ("Cen", "Centaurus", "Centauri"), ("Cep", "Cepheus", "Cephei"),
    ("Cet", "Cetus", "Ceti"), ("Cha", "Chamaeleon", "Chamaeleontis"),
    ("Cir", "Circinus", "Circini"), ("Col", "Columba", "Columbae"),
    ("Com", "Coma Berenices", "Comae Berenices"), ("CrA", "Corona Australis", "Coronae Australis"),
    ("CrB", "Corona Borealis", "Coronae Borealis"), ("Crv", "Corvus", "Corvi"),
    ("Crt", "Crater", "Crateris"), ("Cru", "Crux", "Crucis"),
    ("Cyg", "Cygnus", "Cygni"), ("Del", "Delphinus", "Delphini"),
    ("Dor", "Dorado", "Doradus"), ("Dra", "Draco", "Draconis"),
    ("Equ", "Equuleus", "Equulei"), ("Eri", "Eridanus", "Eridani"),
    ("For", "Fornax", "Fornacis"), ("Gem", "Gemini", "Geminorum"),
    ("Gru", "Grus", "Gruis"), ("Her", "Hercules", "Herculis"),
    ("Hor", "Horologium", "Horologii"), ("Hya", "Hydra", "Hydrae"),
    ("Hyi", "Hydrus", "Hydri"), ("Ind", "Indus", "Indi"),
    ("Lac", "Lacerta", "Lacertae"), ("Leo", "Leo", "Leonis"),
    ("LMi", "Leo Minor", "Leonis Minoris"), ("Lep", "Lepus", "Leporis"),
    ("Lib", "Libra", "Librae"), ("Lup", "Lupus", "Lupi"),
    ("Lyn", "Lynx", "Lyncis"), ("Lyr", "Lyra", "Lyrae"),
    ("Men", "Mensa", "Mensae"), ("Mic", "Microscopium", "Microscopii"),
    ("Mon", "Monoceros", "Monocerotis"), ("Mus", "Musca", "Muscae"),
    ("Nor", "Norma", "Normae"), ("Oct", "Octans", "Octantis"),
    ("Oph", "Ophiuchus", "Ophiuchi"), ("Ori", "Orion", "Orionis"),
    ("Pav", "Pavo", "Pavonis"), ("Peg", "Pegasus", "Pegasi"),
    ("Per", "Perseus", "Persei"), ("Phe", "Phoenix", "Phoenicis"),
    ("Pic", "Pictor", "Pictoris"), ("Psc", "Pisces", "Piscium"),
    ("PsA", "Piscis Austrinus", "Piscis Austrini"), ("Pup", "Puppis", "Puppis"),
    ("Pyx", "Pyxis", "Pyxidis"), ("Ret", "Reticulum", "Reticuli"),
    ("Sge", "Sagitta", "Sagittae"), ("Sgr", "Sagittarius", "Sagittarii"),
    ("Sco", "Scorpius", "Scorpii"), ("Scl", "Sculptor", "Sculptoris"),
    ("Sct", "Scutum", "Scuti"), ("Ser", "Serpens", "Serpentis"),
    ("Sex", "Sextans", "Sextantis"), ("Tau", "Taurus", "Tauri"),
    ("Tel", "Telescopium", "Telescopii"), ("Tri", "Triangulum", "Trianguli"),
    ("TrA", "Triangulum Australe", "Trianguli Australis"), ("Tuc", "Tucana", "Tucanae"),
    ("UMa", "Ursa Major", "Ursae Majoris"), ("UMi", "Ursa Minor", "Ursae Minoris"),
    ("Vel", "Vela", "Velorum"), ("Vir", "Virgo", "Virginis"),
    ("Vol", "Volans", "Volantis"), ("Vul", "Vulpecula", "Vulpeculae"),
)

_GREEK_TO_ABBR: dict[str, str] = {}
for _abbr, _full, _letter in GREEK_LETTERS:
    _GREEK_TO_ABBR[_abbr] = _GREEK_TO_ABBR[_full] = _GREEK_TO_ABBR[_letter] = _abbr
_GREEK_TO_ABBR["xi"] = "ksi"
_GREEK_TO_ABBR["the"] = "tet"  # BSC spelling "The" for theta
_GREEK_TO_ABBR["ϑ"] = "tet"

_CON_TO_ABBR: dict[str, str] = {}
for _abbr, _name, _gen in CONSTELLATIONS:
    for _form in (_abbr, _name, _gen):
        _CON_TO_ABBR[re.sub(r"[^a-z]", "", _form.lower())] = _abbr.lower()

_SUPERSCRIPTS = str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹", "0123456789")
# "<greek><component> <constellation>", e.g. "alpha", "π²", "pi.02" then "Ori"/"Orionis".
_DESIGNATION = re.compile(r"^\s*([^\W\d_]+)[\s.]*0*(\d?)[\s._-]*([a-z][a-z\s]*?)\s*$")
_FLAMSTEED = re.compile(r"^\s*(\d{1,3})[\s._-]*([a-z][a-z\s]*?)\s*$")


def plain_key(text: str) -> str:
    """Lower-case *text* and drop accents, spaces and punctuation: 'Rigil Kent.' -> 'rigilkent'."""
    decomposed = unicodedata.normalize("NFKD", text.translate(_SUPERSCRIPTS))
    return "".join(c for c in decomposed.lower() if c.isalnum() and not unicodedata.combining(c))


def designation_key(text: str) -> str | None:
    """Return the key of a Bayer or Flamsteed designation, or None if *text* is not one.

    'Alpha Lyrae', 'alf Lyr', 'α Lyr' -> 'alflyr'; 'pi2 Ori' -> 'pi2ori'; '3 Lyr' -> '3lyr'.
    """
    lowered = text.translate(_SUPERSCRIPTS).lower().replace("-", " ")
    m = _DESIGNATION.match(lowered)
    if m and m.group(1) in _GREEK_TO_ABBR:
        con = _CON_TO_ABBR.get(re.sub(r"[^a-z]", "", m.group(3)))
        if con:
            return f"{_GREEK_TO_ABBR[m.group(1)]}{m.group(2)}{con}"
    m = _FLAMSTEED.match(lowered)
    if m:
        con = _CON_TO_ABBR.get(re.sub(r"[^a-z]", "", m.group(2)))
        if con:
            return f"{int(m.group(1))}{con}"
    return None
