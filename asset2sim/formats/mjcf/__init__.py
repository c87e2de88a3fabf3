"""MJCF (MuJoCo): the files a model names, gathered under the reader policy (:mod:`.files`), the conventions
its host package compiles it with (:mod:`.conventions`), the object in a scene (:mod:`.scene`), the reader
(:mod:`.reader`), the export of an output folder (:mod:`.export`) and the one physics writer (:mod:`.physics`)."""
