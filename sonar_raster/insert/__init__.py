"""Insert rendered objects, their shadows and their labels into real side-scan recordings.

The job, top to bottom: read a recording and bottom-track it (:mod:`.recording`); build the
objects (:mod:`.objects`) and stand them on its seabed inside the swath (:mod:`.placement`);
render the seabed alone, with the objects, and with dark objects, with the recording's
per-ping geometry (:mod:`.scene`); composite the objects' returns and shadows with the
recording's gain, speckle and noise floor, and label them (:mod:`.composite`); write the
recording back as XTF (:mod:`.xtf_patch`) with its PNG and labels (:mod:`.outputs`).
"""

from .insertion import Insertion, insert_objects
from .objects import ObjectMesh, object_mesh
from .recording import Recording, read_recording, recording_from_image

__all__ = [
    "Insertion",
    "ObjectMesh",
    "Recording",
    "insert_objects",
    "object_mesh",
    "read_recording",
    "recording_from_image",
]
