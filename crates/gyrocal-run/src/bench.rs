//! The bench: the instruments a run uses, provided by role.
//!
//! Why a trait with associated types: the engine is generic over its instruments (the same
//! code drives real instruments and the simulated bench, in real or virtual time), and a
//! generic parameter per role would put every role in every generic signature and call site
//! (`Engine<M, T>`, then `Engine<M, T, C>` when a temperature chamber arrives, ...). With
//! `Engine<B: Bench>` a new role is one more associated type here and one more method, with
//! an absent-instrument type (like [`gyrocal_table::NoTable`]) for benches without it.
//!
//! Roles today: the multimeter (always), the rate table ([`gyrocal_table::NoTable`] when
//! the plan has none) and the thermal chamber of a temperature series
//! ([`gyrocal_chamber::NoChamber`] on every other bench: [`MeterAndTable`]; a series runs on
//! [`MeterTableChamber`]). Room is left for:
//!
//! - a power supply (`type Supply: Supply`, `NoSupply`): a turn-on repeatability test
//!   switches the gyro's supply between records.

use gyrocal_chamber::{Chamber, NoChamber};
use gyrocal_meter::Multimeter;
use gyrocal_table::RateTable;

/// The instruments of a run, by role. The engine asks for a role when a step needs it, and
/// for both at once when a step overlaps them (a memory burst fetched while the table
/// ramps: they are on separate ports).
pub trait Bench: Send {
    /// The multimeter reading the gyro's output.
    type Meter: Multimeter;
    /// The rate table ([`gyrocal_table::NoTable`] when the run has none).
    type Table: RateTable;
    /// The thermal chamber ([`NoChamber`] when the run has none).
    type Chamber: Chamber;

    /// The multimeter.
    fn meter(&mut self) -> &mut Self::Meter;
    /// The rate table.
    fn table(&mut self) -> &mut Self::Table;
    /// Both at once, for steps that use them concurrently.
    fn meter_and_table(&mut self) -> (&mut Self::Meter, &mut Self::Table);
    /// The thermal chamber.
    fn chamber(&mut self) -> &mut Self::Chamber;
    /// All three at once: a step at a temperature reads the chamber while the meter
    /// acquires and the table is sampled (each on its own port).
    fn instruments(&mut self) -> (&mut Self::Meter, &mut Self::Table, &mut Self::Chamber);
}

/// The bench of today's runs: a multimeter and a rate table (or [`gyrocal_table::NoTable`]).
#[derive(Debug)]
pub struct MeterAndTable<M, T> {
    meter: M,
    table: T,
    /// Always absent: answers nothing, and its safe state is trivially confirmed.
    chamber: NoChamber,
}

impl<M: Multimeter, T: RateTable> MeterAndTable<M, T> {
    /// A bench of `meter` and `table`.
    pub fn new(meter: M, table: T) -> Self {
        MeterAndTable {
            meter,
            table,
            chamber: NoChamber,
        }
    }

    /// The instruments back.
    pub fn into_parts(self) -> (M, T) {
        (self.meter, self.table)
    }
}

impl<M: Multimeter, T: RateTable> Bench for MeterAndTable<M, T> {
    type Meter = M;
    type Table = T;
    type Chamber = NoChamber;

    fn meter(&mut self) -> &mut M {
        &mut self.meter
    }

    fn table(&mut self) -> &mut T {
        &mut self.table
    }

    fn meter_and_table(&mut self) -> (&mut M, &mut T) {
        (&mut self.meter, &mut self.table)
    }

    fn chamber(&mut self) -> &mut NoChamber {
        &mut self.chamber
    }

    fn instruments(&mut self) -> (&mut M, &mut T, &mut NoChamber) {
        (&mut self.meter, &mut self.table, &mut self.chamber)
    }
}

/// The bench of a temperature series: a multimeter, a rate table and a thermal chamber.
#[derive(Debug)]
pub struct MeterTableChamber<M, T, C> {
    meter: M,
    table: T,
    chamber: C,
}

impl<M: Multimeter, T: RateTable, C: Chamber> MeterTableChamber<M, T, C> {
    /// A bench of `meter`, `table` and `chamber`.
    pub fn new(meter: M, table: T, chamber: C) -> Self {
        MeterTableChamber {
            meter,
            table,
            chamber,
        }
    }

    /// The instruments back.
    pub fn into_parts(self) -> (M, T, C) {
        (self.meter, self.table, self.chamber)
    }
}

impl<M: Multimeter, T: RateTable, C: Chamber> Bench for MeterTableChamber<M, T, C> {
    type Meter = M;
    type Table = T;
    type Chamber = C;

    fn meter(&mut self) -> &mut M {
        &mut self.meter
    }

    fn table(&mut self) -> &mut T {
        &mut self.table
    }

    fn meter_and_table(&mut self) -> (&mut M, &mut T) {
        (&mut self.meter, &mut self.table)
    }

    fn chamber(&mut self) -> &mut C {
        &mut self.chamber
    }

    fn instruments(&mut self) -> (&mut M, &mut T, &mut C) {
        (&mut self.meter, &mut self.table, &mut self.chamber)
    }
}
