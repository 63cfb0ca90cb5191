//! Typed access to the columns of a batch read back from a table: one place that knows
//! how to find a column, check its type and say which table it came from.

use deltalake::arrow::array::{Array, Float32Array, Int32Array, ListArray, RecordBatch, StringArray};

use crate::error::{Error, Result};
use crate::schema::TableKind;

/// Column `name` of `batch` (a batch of `table`) as an Arrow array of type `T`.
pub(crate) fn column<'a, T: 'static>(batch: &'a RecordBatch, name: &str, table: TableKind) -> Result<&'a T> {
    batch
        .column_by_name(name)
        .and_then(|c| c.as_any().downcast_ref::<T>())
        .ok_or_else(|| Error::Schema {
            table: table.name().into(),
            msg: format!("column {name} missing or of an unexpected type"),
        })
}

/// Row `i` of a nullable string column.
pub(crate) fn opt_str(a: &StringArray, i: usize) -> Option<String> {
    a.is_valid(i).then(|| a.value(i).to_string())
}

/// Row `i` of a nullable `list<float32>` column.
pub(crate) fn opt_f32s(a: &ListArray, i: usize) -> Option<Vec<f32>> {
    if a.is_null(i) {
        return None;
    }
    a.value(i)
        .as_any()
        .downcast_ref::<Float32Array>()
        .map(|f| f.values().to_vec())
}

/// Row `i` of a nullable `list<string>` column.
pub(crate) fn opt_strs(a: &ListArray, i: usize) -> Option<Vec<String>> {
    if a.is_null(i) {
        return None;
    }
    let v = a.value(i);
    let s = v.as_any().downcast_ref::<StringArray>()?;
    Some((0..s.len()).map(|j| s.value(j).to_string()).collect())
}

/// Row `i` of a nullable `list<int32>` column.
pub(crate) fn opt_i32s(a: &ListArray, i: usize) -> Option<Vec<i32>> {
    if a.is_null(i) {
        return None;
    }
    a.value(i)
        .as_any()
        .downcast_ref::<Int32Array>()
        .map(|f| f.values().to_vec())
}
