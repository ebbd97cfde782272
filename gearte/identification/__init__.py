"""From a measured TE record back to the parts: reading records, identifying a drive's errors, diagnosing
the record's lines, and assembling measured parts (one drive, or a batch by selective assembly)."""

from .assembly import BatchAssembly as BatchAssembly
from .assembly import assemble_batch as assemble_batch
from .assembly import reassemble as reassemble
from .diagnosis import Diagnosis as Diagnosis
from .diagnosis import LineDiagnosis as LineDiagnosis
from .diagnosis import diagnose as diagnose
from .fit import (
    Group as Group,
)
from .fit import (
    Identification as Identification,
)
from .fit import (
    IdentificationProblem as IdentificationProblem,
)
from .fit import (
    identification_problem as identification_problem,
)
from .fit import (
    identify as identify,
)
from .records import (
    MeasuredRecord as MeasuredRecord,
)
from .records import (
    RecordError as RecordError,
)
from .records import (
    read_record as read_record,
)
from .records import (
    record_from_columns as record_from_columns,
)
from .records import (
    resample as resample,
)
from .records import (
    synthetic_record as synthetic_record,
)
from .records import (
    write_record as write_record,
)
