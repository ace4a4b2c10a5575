"""Input formats: the files engineers bring, read into the recording contract. DAQ files and their
channel maps (``daq_import``), plain tables of channels (``tables``), the table ``shm oma`` identifies
from (``oma_input``), the counted rejections of single samples a reader refused (``rejections``) and
DAQ files with field faults for the campaigns (``daq_faults``). May import ``contract`` and
``shm_service.recording``; nothing of the service or the commands.
"""
