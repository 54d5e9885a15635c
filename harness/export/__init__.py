"""Writing models for other programs: ParaView VTU, engine JSON (Newton/Warp/Taichi, SOFA)."""
