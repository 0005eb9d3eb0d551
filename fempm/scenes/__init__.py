"""Built-in scenes (the verification problems), usable from Python and from
``python -m fempm run NAME --option value``; one scene per module."""

from fempm.scenes.bar import vibrating_bar
from fempm.scenes.bowl import bowl
from fempm.scenes.block import hanging_block, largest_neighbour_gap
from fempm.scenes.cantilever import cantilever, cantilever_reference, cantilever_tip
from fempm.scenes.column import column_collapse, deposit
from fempm.scenes.compaction import compaction, stress_error
from fempm.scenes.cook import cook_membrane
from fempm.scenes.dam import MARTIN_MOYCE, dam_break, surge_front
from fempm.scenes.disks import two_disks
from fempm.scenes.footing import footing
from fempm.scenes.impact import disk_impact
from fempm.scenes.incline import incline
from fempm.scenes.manufactured import manufactured_scene
from fempm.scenes.silo import silo
from fempm.scenes.spin import spin
from fempm.scenes.wave import wave

SCENES = {"bar": vibrating_bar, "disks": two_disks, "cantilever": cantilever, "dam": dam_break, "block": hanging_block,
          "cook": cook_membrane, "column": column_collapse, "incline": incline, "impact": disk_impact,
          "compaction": compaction, "wave": wave, "footing": footing, "silo": silo, "bowl": bowl, "spin": spin}

__all__ = [
    "MARTIN_MOYCE", "SCENES", "bowl", "cantilever", "cantilever_reference", "cantilever_tip", "column_collapse", "compaction",
    "cook_membrane",
    "dam_break", "deposit", "disk_impact", "footing",
    "hanging_block", "incline",
    "largest_neighbour_gap", "manufactured_scene",
    "silo", "spin", "stress_error", "surge_front", "two_disks", "vibrating_bar", "wave",
]
