"""Reads two frame series of a granite run with VTK's own readers and says whether they hold the
same frames: the same times, and in each frame and picture the same points, cells and arrays,
value for value.

A series is a `.vtkhdf` file (read by vtkHDFReader, one block a picture) or a `vtk/` folder of
XML frames (`<picture>.pvd` indices of `.vtu` / `.vtp` files).

    python3 compare_frames.py SERIES_A SERIES_B

Prints one line `frames F pictures P arrays A values V` and exits 0 when they are equal; prints
the first difference and exits 1 otherwise. Needs the `vtk` package (pip install vtk).
"""

import os
import re
import sys

import numpy as np
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
from vtkmodules.vtkIOHDF import vtkHDFReader
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader, vtkXMLUnstructuredGridReader


def cells_of(data):
    """Each cell's point ids, in VTK's cell order."""
    cells = []
    if data is None:
        return cells
    if data.IsA("vtkPolyData"):
        arrays = [data.GetVerts(), data.GetLines(), data.GetPolys(), data.GetStrips()]
    else:
        arrays = [data.GetCells()]
    for array in arrays:
        if array is None or array.GetNumberOfCells() == 0:
            continue
        offsets = vtk_to_numpy(array.GetOffsetsArray())
        ids = vtk_to_numpy(array.GetConnectivityArray())
        cells.extend(tuple(ids[a:b].tolist()) for a, b in zip(offsets[:-1], offsets[1:]))
    return cells


def picture(data):
    """Points, cells, and arrays by name of one picture (None: nothing)."""
    if data is None or data.GetNumberOfPoints() == 0:
        return {"points": np.zeros((0, 3)), "cells": [], "point": {}, "cell": {}}
    out = {"points": vtk_to_numpy(data.GetPoints().GetData()), "cells": cells_of(data)}
    for kind, attributes in (("point", data.GetPointData()), ("cell", data.GetCellData())):
        out[kind] = {}
        for k in range(attributes.GetNumberOfArrays()):
            array = attributes.GetArray(k)
            out[kind][array.GetName()] = vtk_to_numpy(array)
    return out


def read_vtkhdf(path):
    reader = vtkHDFReader()
    reader.SetFileName(path)
    reader.UpdateInformation()
    info = reader.GetOutputInformation(0)
    times = list(info.Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS()) or [])
    if len(times) != reader.GetNumberOfSteps():
        raise SystemExit(f"{path}: {reader.GetNumberOfSteps()} steps but {len(times)} time values")
    frames = []
    for step in range(reader.GetNumberOfSteps()):
        reader.SetStep(step)
        reader.Update()
        collection = reader.GetOutputDataObject(0)
        pictures = {}
        for b in range(collection.GetNumberOfPartitionedDataSets()):
            name = collection.GetMetaData(b).Get(collection.NAME())
            partitioned = collection.GetPartitionedDataSet(b)
            data = partitioned.GetPartition(0) if partitioned.GetNumberOfPartitions() else None
            pictures[name] = picture(data)
        frames.append((times[step], pictures))
    return frames


def read_xml_folder(folder):
    series = {}
    for pvd in sorted(f for f in os.listdir(folder) if f.endswith(".pvd")):
        text = open(os.path.join(folder, pvd)).read()
        entries = re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', text)
        series[pvd[:-4]] = [(float(t), os.path.join(folder, f)) for t, f in entries]
    counts = {len(entries) for entries in series.values()}
    if len(counts) != 1:
        raise SystemExit(f"{folder}: the pictures have different frame counts {counts}")
    frames = []
    for k in range(counts.pop()):
        pictures = {}
        time = None
        for name, entries in series.items():
            t, path = entries[k]
            time = t if time is None else time
            reader = vtkXMLPolyDataReader() if path.endswith(".vtp") else vtkXMLUnstructuredGridReader()
            reader.SetFileName(path)
            reader.Update()
            pictures[name] = picture(reader.GetOutput())
        frames.append((time, pictures))
    return frames


def read(series):
    return read_vtkhdf(series) if series.endswith(".vtkhdf") else read_xml_folder(series)


def main():
    a, b = sys.argv[1], sys.argv[2]
    frames_a, frames_b = read(a), read(b)
    if len(frames_a) != len(frames_b):
        raise SystemExit(f"{len(frames_a)} frames in {a}, {len(frames_b)} in {b}")
    arrays = values = 0
    for k, ((ta, pa), (tb, pb)) in enumerate(zip(frames_a, frames_b)):
        if ta != tb:
            raise SystemExit(f"frame {k}: time {ta!r} in {a}, {tb!r} in {b}")
        if sorted(pa) != sorted(pb):
            raise SystemExit(f"frame {k}: pictures {sorted(pa)} in {a}, {sorted(pb)} in {b}")
        for name in pa:
            x, y = pa[name], pb[name]
            where = f"frame {k} (t = {ta}), picture {name}"
            if not np.array_equal(x["points"], y["points"]):
                raise SystemExit(f"{where}: points differ")
            if x["cells"] != y["cells"]:
                raise SystemExit(f"{where}: cells differ ({len(x['cells'])} and {len(y['cells'])})")
            for kind in ("point", "cell"):
                if sorted(x[kind]) != sorted(y[kind]):
                    raise SystemExit(f"{where}: {kind} arrays {sorted(x[kind])} and {sorted(y[kind])}")
                for array in x[kind]:
                    u, v = x[kind][array], y[kind][array]
                    if u.shape != v.shape or not np.array_equal(u, v):
                        raise SystemExit(f"{where}: {kind} array {array} differs: {u.shape} and {v.shape}")
                    arrays += 1
                    values += u.size
    pictures = len(frames_a[0][1]) if frames_a else 0
    print(f"frames {len(frames_a)} pictures {pictures} arrays {arrays} values {values}")


if __name__ == "__main__":
    main()
