from pickplace.v1 import common_pb2 as _common_pb2
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class StreamMetricsRequest(_message.Message):
    __slots__ = ("period_s",)
    PERIOD_S_FIELD_NUMBER: _ClassVar[int]
    period_s: float
    def __init__(self, period_s: _Optional[float] = ...) -> None: ...

class MetricsSample(_message.Message):
    __slots__ = ("header", "cycle_time", "success_rate", "picks_today", "picks_total", "state", "database_ok")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    CYCLE_TIME_FIELD_NUMBER: _ClassVar[int]
    SUCCESS_RATE_FIELD_NUMBER: _ClassVar[int]
    PICKS_TODAY_FIELD_NUMBER: _ClassVar[int]
    PICKS_TOTAL_FIELD_NUMBER: _ClassVar[int]
    STATE_FIELD_NUMBER: _ClassVar[int]
    DATABASE_OK_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    cycle_time: float
    success_rate: float
    picks_today: int
    picks_total: int
    state: str
    database_ok: bool
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., cycle_time: _Optional[float] = ..., success_rate: _Optional[float] = ..., picks_today: _Optional[int] = ..., picks_total: _Optional[int] = ..., state: _Optional[str] = ..., database_ok: _Optional[bool] = ...) -> None: ...
