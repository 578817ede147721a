"""Words in messages: the indefinite article of a noun a message fills in (``a wall``, ``an obstacle``).

A message written as ``f"a {kind}"`` reads "a obstacle" or "a outside stall" when ``kind`` starts with a vowel
sound; :func:`a_noun` picks the article, and writes a code's underscores as spaces (``parked_car``: "a parked car").
"""

from __future__ import annotations

import re

#: Words starting with a vowel letter that sound like a consonant ("a unique ...", "a one-way ...").
_CONSONANT_SOUND = re.compile(r"(uni|use|usa|usu|ure|eu|one|once|ubiq)", re.IGNORECASE)
#: Numbers said with a vowel first: 8, 11, 18, 80-89, 8xx, 11xx ... ("an 84 x 84 camera", "an 11 m slot").
_VOWEL_NUMBER = re.compile(r"(8|11(\D|$)|11\d{2}(\D|$)|18(\D|$)|18\d{2}(\D|$))")


def article(word: object) -> str:
    """``"an"`` before a word said with a vowel first (``obstacle``, ``outside stall``, ``84``), else ``"a"``."""
    w = str(word).strip().lstrip("'\"(`")
    if not w:
        return "a"
    if w[0].isdigit():
        return "an" if _VOWEL_NUMBER.match(w) else "a"
    if w[0].lower() in "aeiou" and not _CONSONANT_SOUND.match(w):
        return "an"
    return "a"


def a_noun(noun: object) -> str:
    """``noun`` with its indefinite article, underscores as spaces: ``an obstacle``, ``a parked car``."""
    words = str(noun).replace("_", " ")
    return f"{article(words)} {words}"
