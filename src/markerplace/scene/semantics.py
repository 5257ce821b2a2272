"""What a mesh part's names say it is: the word list that keeps tags off windows, doors,
curtains, mirrors, screens, pictures and furniture.

A tag belongs on structure that stays (walls, columns). Files often say what a part is: glTF
node, mesh and material names (``RoomWindow_3``, ``FoldingDoor_1``, ``Curtain_2``,
``window.001``, ``Bookcase``), IFC classes carried into node names by ``scripts/ifc_to_glb.py``
(``IfcWindow_1234_0``), and the procedural scenes' labels (``bookshelf``, ``door``).
:func:`classify` reads them with the word list below; the candidate rules of
:mod:`markerplace.plan.discretize.wall_candidates` drop spots on the categories the user does not allow
(``plan --allow``, docs/cli.md).

Matching (:func:`words_of`, :func:`classify`):

* Each name is cut into words at anything that is not a letter or digit, at lower-to-upper case
  changes (``FoldingDoor`` -> folding, door; ``IfcWindow`` -> ifc, window; ``TVStand`` -> tv,
  stand), between letters and digits (``Door12``) and into or out of CJK script.
* A word matches an entry of :data:`WORDS` whole, compared lower-cased with accents folded
  (``Tür`` = tur, ``ß`` = ss), also after dropping a plural ``s``/``es``; two neighbouring words
  also match as one (``Book_Case`` -> bookcase; ``IfcCurtainWall`` -> curtainwall, a glass
  facade, not a curtain). English words match whole only (``outdoor`` is no door).
* Compound-forming languages (German, Dutch, Scandinavian) glue words together (``Haustür``,
  ``Kleiderschrank``, ``boekenkast``): the :data:`STEMS` match at the start or the end of a
  longer word, with their accents (``Struktur`` is no ``Tür``). In scripts written without
  spaces (Chinese, Japanese) they match anywhere; a longer stem containing a shorter one wins
  (窗帘, curtain, over 窗, window).
* Every name of a part counts (node and its parents, mesh, material). When they name several
  categories, the first in :data:`CATEGORIES` order wins (a ``Window`` node's ``Frame`` child
  is a window; a ``DoorFrame``, or a ``Door`` with a ``Glass`` material, a door).
  :data:`STRUCTURE` words (wall, column, ...) count only when no category is named.

The names a file gives are guesses by whoever made it; the geometric rules of
:mod:`markerplace.plan.discretize.wall_candidates` catch what no name says.
"""

from __future__ import annotations

import unicodedata
from dataclasses import dataclass
from typing import Iterable

__all__ = ["CATEGORIES", "STRUCTURE", "STEMS", "WORDS", "PartKind", "classify", "words_of"]

CATEGORIES: dict[str, str] = {
    "doors": "doors of any kind (hinged, sliding, folding, glass or not) and their frames",
    "windows": "windows, skylights, glazing and glass facades (curtain walls)",
    "curtains": "curtains, drapes and blinds",
    "mirrors": "mirrors",
    "screens": "TVs, monitors, displays and projection screens",
    "furniture": "furniture and fittings: bookcases, shelves, cabinets, wardrobes, kitchen units, appliances",
    "pictures": "pictures, paintings, posters, photos, frames, whiteboards",
}
"""The categories a name can put a part in (``plan --allow`` names them), in priority order."""

# word -> the English noun the report uses ("bookcase front", "door", ...). Keys are matched
# after folding (lower case, accents dropped), so "tür" and "tur" are the same key.
WORDS: dict[str, dict[str, str]] = {
    "windows": {
        "window": "window", "windowpane": "window", "pane": "window pane", "skylight": "skylight",
        "rooflight": "skylight", "glazing": "glazing", "glass": "glass", "casement": "window",
        "curtainwall": "glass facade", "storefront": "glass facade",
        "fenster": "window", "glas": "glass", "fenêtre": "window", "vitre": "window", "verre": "glass",
        "ventana": "window", "vidrio": "glass", "cristal": "glass", "finestra": "window", "vetro": "glass",
        "janela": "window", "vidro": "glass", "raam": "window", "venster": "window", "okno": "window",
        "fönster": "window", "vindu": "window", "vindue": "window", "ikkuna": "window", "pencere": "window",
        "окно": "window", "окна": "window",
    },
    "doors": {
        "door": "door", "doorleaf": "door", "doorframe": "door frame", "doorway": "doorway", "gate": "gate",
        "tür": "door", "tuer": "door", "türe": "door", "porte": "door", "puerta": "door", "porta": "door",
        "portone": "door", "deur": "door", "drzwi": "door", "dveře": "door", "dörr": "door", "dør": "door",
        "ovi": "door", "kapı": "door", "дверь": "door", "двери": "door",
    },
    "curtains": {
        "curtain": "curtain", "drape": "curtain", "drapery": "curtain", "blind": "blind", "blinds": "blind",
        "vorhang": "curtain", "gardine": "curtain", "rollo": "blind", "jalousie": "blind", "rideau": "curtain",
        "voilage": "curtain", "cortina": "curtain", "persiana": "blind", "tenda": "curtain", "gordijn": "curtain",
        "zasłona": "curtain", "firana": "curtain", "штора": "curtain", "занавеска": "curtain",
    },
    "mirrors": {
        "mirror": "mirror", "spiegel": "mirror", "miroir": "mirror", "espejo": "mirror", "specchio": "mirror",
        "espelho": "mirror", "lustro": "mirror", "zrcadlo": "mirror", "зеркало": "mirror",
    },
    "screens": {
        "tv": "TV", "television": "TV", "telly": "TV", "screen": "screen", "monitor": "monitor",
        "display": "display", "projector": "projection screen", "fernseher": "TV", "bildschirm": "screen",
        "écran": "screen", "téléviseur": "TV", "pantalla": "screen", "televisor": "TV", "schermo": "screen",
        "televisore": "TV", "beeldscherm": "screen", "telewizor": "TV", "телевизор": "TV", "экран": "screen",
    },
    "furniture": {
        "furniture": "furniture", "furnishing": "furniture", "bookcase": "bookcase", "bookshelf": "bookshelf",
        "shelf": "shelf", "shelves": "shelf", "shelving": "shelf", "rack": "rack", "cabinet": "cabinet",
        "cupboard": "cupboard", "closet": "closet", "wardrobe": "wardrobe", "armoire": "wardrobe",
        "dresser": "dresser", "drawer": "drawer", "chest": "chest", "sideboard": "sideboard",
        "credenza": "sideboard", "locker": "locker", "vitrine": "display cabinet", "nightstand": "nightstand",
        "counter": "counter", "countertop": "counter", "worktop": "counter", "island": "kitchen island",
        "fridge": "fridge", "refrigerator": "fridge", "freezer": "freezer", "oven": "oven",
        "dishwasher": "dishwasher", "stand": "stand", "desk": "desk", "table": "table", "chair": "chair",
        "sofa": "sofa", "couch": "sofa", "armchair": "armchair", "bed": "bed", "headboard": "bed",
        "bench": "bench", "stool": "stool", "printer": "printer", "sink": "sink", "bathtub": "bathtub",
        "plant": "plant", "lamp": "lamp",
        "schrank": "cupboard", "regal": "shelf", "kommode": "dresser", "möbel": "furniture",
        "étagère": "shelf", "bibliothèque": "bookcase", "placard": "cupboard", "meuble": "furniture",
        "estantería": "shelf", "armario": "cupboard", "estante": "shelf", "mueble": "furniture",
        "scaffale": "shelf", "armadio": "cupboard", "libreria": "bookcase", "kast": "cupboard",
        "boekenkast": "bookcase", "szafa": "wardrobe", "regał": "shelf", "skåp": "cupboard", "hylla": "shelf",
        "kaappi": "cupboard", "dolap": "cupboard", "шкаф": "cupboard", "полка": "shelf", "стеллаж": "shelf",
    },
    "pictures": {
        "picture": "picture", "pic": "picture", "painting": "painting", "poster": "poster", "photo": "photo",
        "photograph": "photo", "frame": "frame", "artwork": "artwork", "canvas": "canvas",
        "whiteboard": "whiteboard", "blackboard": "blackboard", "bild": "picture", "gemälde": "painting",
        "rahmen": "frame", "tableau": "picture", "cadre": "frame", "affiche": "poster", "cuadro": "picture",
        "marco": "frame", "quadro": "picture", "cornice": "frame", "dipinto": "painting",
        "schilderij": "painting", "lijst": "frame", "obraz": "picture", "tavla": "picture",
        "картина": "picture", "рамка": "frame",
    },
}
"""Per category: word -> the English noun it means. Matched whole (see the module docstring)."""

STEMS: dict[str, dict[str, str]] = {
    "windows": {"fenster": "window", "raam": "window", "venster": "window", "fönster": "window",
                "vindu": "window", "ikkuna": "window", "窗": "window"},
    "doors": {"tür": "door", "tuer": "door", "deur": "door", "dörr": "door", "dør": "door",
              "門": "door", "门": "door", "ドア": "door", "扉": "door"},
    "curtains": {"vorhang": "curtain", "gardine": "curtain", "gordijn": "curtain", "窗帘": "curtain",
                 "窗簾": "curtain", "カーテン": "curtain"},
    "mirrors": {"spiegel": "mirror", "镜": "mirror", "鏡": "mirror"},
    "screens": {"fernseher": "TV", "bildschirm": "screen", "电视": "TV", "電視": "TV", "テレビ": "TV"},
    "furniture": {"schrank": "cupboard", "regal": "shelf", "kommode": "dresser", "möbel": "furniture",
                  "kast": "cupboard", "skåp": "cupboard", "hylla": "shelf", "kaappi": "cupboard",
                  "柜": "cabinet", "櫃": "cabinet", "书架": "bookcase", "書架": "bookcase", "棚": "shelf"},
    "pictures": {"bild": "picture", "rahmen": "frame", "gemälde": "painting", "schilderij": "painting",
                 "画": "picture", "絵": "picture"},
}
"""Per category: parts of compound words (``Haustür``, ``Kleiderschrank``, ``boekenkast``),
matched at the start or the end of a longer word, with its accents (``Struktur`` is no ``Tür``);
in scripts without spaces (Chinese, Japanese) anywhere in the name."""

STRUCTURE: dict[str, str] = {
    "wall": "wall", "partition": "wall", "column": "column", "pillar": "column", "pier": "column",
    "post": "column", "wand": "wall", "mauer": "wall", "stütze": "column", "säule": "column",
    "pfeiler": "column", "mur": "wall", "cloison": "wall", "colonne": "column", "pilier": "column",
    "pared": "wall", "muro": "wall", "columna": "column", "pilar": "column", "parete": "wall",
    "colonna": "column", "pilastro": "column", "parede": "wall", "coluna": "column", "muur": "wall",
    "kolom": "column", "pilaar": "column", "ściana": "wall", "kolumna": "column", "стена": "wall",
    "колонна": "column", "墙": "wall", "牆": "wall", "壁": "wall", "柱": "column",
}
"""Words of structure that stays; they name a surface ``wall`` or ``column`` when no category is
named (matched whole; the CJK ones anywhere in a name)."""

_FOLD = str.maketrans({"ß": "ss", "ẞ": "ss", "ø": "o", "Ø": "o", "æ": "ae", "Æ": "ae", "œ": "oe", "Œ": "oe",
                       "ı": "i", "ł": "l", "Ł": "l", "đ": "d", "Đ": "d"})


@dataclass(frozen=True)
class PartKind:
    """What a part's names say.

    Attributes:
        category: a key of :data:`CATEGORIES`, ``"structure"`` (a wall or column word and no
            category), or ``""`` (the names say nothing).
        noun: the English noun of the matched word (``"bookcase"``, ``"door"``, ``"wall"``,
            ``"column"``), ``""`` when nothing matched.
        word: the word as found (folded, e.g. ``"kleiderschrank"``), ``""`` when nothing matched.
    """

    category: str = ""
    noun: str = ""
    word: str = ""


def _fold(text: str) -> str:
    """Lower case, accents dropped (NFKD without combining marks; ß -> ss, ø -> o, ...)."""
    text = unicodedata.normalize("NFKD", str(text).translate(_FOLD))
    return "".join(c for c in text if not unicodedata.combining(c)).lower()


def _spaceless(c: str) -> bool:
    """A character of a script written without spaces (CJK ideographs, kana)."""
    return ord(c) >= 0x2E80


def _split(name: str) -> list[str]:
    """Words of one name, as written: cut at non-alphanumerics, lower-to-upper case changes
    (``FoldingDoor``), the last capital of a capital run before a lower-case letter
    (``TVStand`` -> TV, Stand), letter/digit changes and changes into or out of CJK."""
    text = unicodedata.normalize("NFC", str(name))
    words, cur = [], ""
    for i, c in enumerate(text):
        if not c.isalnum():
            if cur:
                words.append(cur)
            cur = ""
            continue
        if cur:
            p, nxt = cur[-1], text[i + 1] if i + 1 < len(text) else ""
            if (c.isdigit() != p.isdigit() or (c.isupper() and p.islower())
                    or (c.isupper() and p.isupper() and nxt.islower()) or _spaceless(c) != _spaceless(p)):
                words.append(cur)
                cur = ""
        cur += c
    if cur:
        words.append(cur)
    return words


def words_of(name: str) -> list[str]:
    """The words of one name, folded (lower case, accents dropped; see the module docstring)."""
    return [_fold(w) for w in _split(name)]


def _folded(table: dict[str, str]) -> dict[str, str]:
    return {_fold(k): v for k, v in table.items()}


_WORDS = {cat: _folded(t) for cat, t in WORDS.items()}
_STRUCTURE = _folded(STRUCTURE)
_STEMS = {cat: {k.lower(): v for k, v in t.items()} for cat, t in STEMS.items()}


def _lookup(word: str, table: dict[str, str]) -> str | None:
    """The key of ``table`` that ``word`` is, or is the plural of (``s``, ``es``), else None."""
    for key in (word, word[:-1] if word.endswith("s") else "", word[:-2] if word.endswith("es") else ""):
        if len(key) >= 2 and key in table:
            return key
    return None


def _matches(name: str) -> list[tuple[str, str, str]]:
    """Every (category, noun, word) one name matches; category ``"structure"`` for structure."""
    raw = [w.lower() for w in _split(name)]
    words = [_fold(w) for w in raw]
    found: list[tuple[str, str, str]] = []
    used = [False] * len(words)
    for i in range(len(words) - 1):  # two neighbouring words as one (Book_Case, IfcCurtainWall)
        joined = words[i] + words[i + 1]
        for cat, table in _WORDS.items():
            key = _lookup(joined, table)
            if key is not None:
                found.append((cat, table[key], joined))
                used[i] = used[i + 1] = True
    for i, (w, r) in enumerate(zip(words, raw)):
        if used[i]:
            continue
        whole = [(cat, table[key], w) for cat, table in _WORDS.items() if (key := _lookup(w, table)) is not None]
        if whole:
            found += whole
            continue
        key = _lookup(w, _STRUCTURE)
        if key is not None:
            found.append(("structure", _STRUCTURE[key], w))
            continue
        stems = []
        for cat, table in _STEMS.items():
            for stem, noun in table.items():
                if _spaceless(stem[0]):
                    hit = stem in r
                else:
                    hit = len(r) > len(stem) and (r.startswith(stem) or r.endswith(stem))
                if hit:
                    stems.append((cat, noun, stem))
        # a longer stem that contains a shorter one wins (窗帘, curtain, over 窗, window)
        stems = [s for s in stems if not any(s[2] != t[2] and s[2] in t[2] for t in stems)]
        found += [(cat, noun, w) for cat, noun, _ in stems]
        if not stems:
            found += [("structure", noun, w) for k, noun in _STRUCTURE.items() if _spaceless(k[0]) and k in r]
    return found


def classify(names: Iterable[str]) -> PartKind:
    """What the names of one part (node, its parents, mesh, material, ...) say it is.

    Returns the first category in :data:`CATEGORIES` order that any name matches, else
    ``"structure"`` when a name is a structure word, else an empty :class:`PartKind`.
    """
    found = [m for name in names if name for m in _matches(str(name))]
    if not found:
        return PartKind()
    order = list(CATEGORIES) + ["structure"]
    cat, noun, word = min(found, key=lambda m: order.index(m[0]))
    return PartKind(cat, noun, word)
