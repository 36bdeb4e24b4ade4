"""Dependency aliases for the routers (sessions, repositories, the running cell, the token check)."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import TYPE_CHECKING, Annotated

from fastapi import Depends, Request
from sqlalchemy.ext.asyncio import AsyncSession

from gateway.db.repository import PickRepository
from gateway.security import require_token

if TYPE_CHECKING:
    from gateway.state import Cell


async def get_cell(request: Request) -> Cell:
    return request.app.state.cell


CellDep = Annotated["Cell", Depends(get_cell)]


async def get_session(request: Request) -> AsyncIterator[AsyncSession]:
    async with request.app.state.cell.sessions() as session:
        yield session


SessionDep = Annotated[AsyncSession, Depends(get_session)]


async def get_picks(session: SessionDep) -> PickRepository:
    return PickRepository(session)


PicksDep = Annotated[PickRepository, Depends(get_picks)]

# Every mutating route carries this.
Authorized = [Depends(require_token)]
