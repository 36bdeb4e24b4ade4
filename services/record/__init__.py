"""Live view in Foxglove, MCAP recording and replay of the cell (issue 17).

Pure cores: :mod:`channels` (topic → schema), :mod:`convert` (bus messages → Foxglove payloads),
:mod:`writer` (MCAP files split by size and time, the writer boundary), :mod:`replay` (reading a
recording back, rebuilding frames, comparing detections). One thin shell: :mod:`service`.
"""
