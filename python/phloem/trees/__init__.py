"""Tree billboards: new trees from a library of RGBA side views, after Argudo et al. 2017, *Tree Variations*.

Each RGBA side view of a tree (an *exemplar*) becomes a fixed-length contour that can be
combined linearly with the contours of other exemplars (§4, §5.1):

1. :func:`normalize` thresholds the alpha channel, blackens transparent pixels, crops to the
   opaque bounding box, pads to a square and resizes (§4.1);
2. :func:`contour` takes the longest exterior contour of the alpha mask, counter-clockwise (§4.2);
3. :func:`segment` separates the trunk from the crown (§4.3; the paper's fine-tuned FCN is
   replaced by a classical width-profile segmenter, or a :class:`TrunkClassifier` trained on a
   few labelled trees, and a user mask can be given instead);
4. :func:`pin_points` finds the tree bottom B and the trunk tops L and R (§4.4);
5. :func:`resample` resamples the contour to 2000 points, 1600 on the crown and 200 on each
   side of the trunk, with uniform chord lengths in each segment (§4.5);
6. :func:`simplify` makes the 100-point contour of the dilated interior used for mean value
   coordinates (§4.6).

:func:`prepare` runs all six and returns a :class:`Tree`; a :class:`Library` holds many.
:func:`split_atlas` cuts an atlas of several billboards (e.g. FlightGear's tree textures) into
single trees first. New trees combine the contours of a few exemplars (:func:`combine_contours`,
§5.1) and fill them by mean value coordinates colour transfer (:func:`morph`, §5.2), optionally
followed by histogram transfer (:func:`match_histograms`, §5.3); :func:`variation` and
:func:`vary` draw the exemplars and weights at random (§3).

Coordinates are ``(x, y)`` pixel positions, origin top-left, ``y`` growing downwards (the
project's convention). *Counter-clockwise* means as seen on the screen, so the paper's "minimum
``y``" (its ``y`` grows upwards) is the *largest* row here.

Modules
-------
atlas          split_atlas, normalize (§4.1)
contours       contour, signed_area, pin_points, resample, simplify (§4.2, §4.4–4.6)
segmentation   segment, crown_baseline (§4.3, training-free)
classifier     TrunkClassifier (§4.3, trained on a few labelled trees)
preprocessing  Tree, prepare (§4, §4.7)
contour_space  combine_contours, fill_contour (§5.1)
transfer       cages, morph, match_histograms (§5.2, §5.3)
library        Library (§3)
synthesis      Variation, variation, vary (§3, §5)
figures        morph_table (Fig. 13, Fig. 14)

References
----------
.. [1] O. Argudo, C. Andújar, A. Chica, "Tree Variations", CEIG 2017 (Eurographics
   Proceedings), doi:10.2312/ceig.20171218.
"""

from __future__ import annotations

from .atlas import normalize, split_atlas
from .classifier import TrunkClassifier
from .contour_space import combine_contours, fill_contour
from .contours import contour, pin_points, resample, signed_area, simplify
from .figures import morph_table
from .library import Library
from .preprocessing import Tree, prepare
from .segmentation import crown_baseline, segment
from .synthesis import Variation, variation, vary
from .transfer import cages, match_histograms, morph

__all__ = [
    "Library",
    "Tree",
    "TrunkClassifier",
    "Variation",
    "cages",
    "combine_contours",
    "contour",
    "crown_baseline",
    "fill_contour",
    "match_histograms",
    "morph",
    "morph_table",
    "normalize",
    "pin_points",
    "prepare",
    "resample",
    "segment",
    "signed_area",
    "simplify",
    "split_atlas",
    "variation",
    "vary",
]
