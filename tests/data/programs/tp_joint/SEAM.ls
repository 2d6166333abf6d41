/PROG  SEAM
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "leadthrough SEAM";
PROG_SIZE	= 0;
FILE_NAME	= SEAM;
VERSION		= 0;
LINE_COUNT	= 10;
MEMORY_SIZE	= 0;
PROTECT		= READ_WRITE;
TCD:  STACK_SIZE	= 0,
      TASK_PRIORITY	= 50,
      TIME_SLICE	= 0,
      BUSY_LAMP_OFF	= 0,
      ABORT_REQUEST	= 0,
      PAUSE_REQUEST	= 0;
DEFAULT_GROUP	= 1,*,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/MN
   1:  ! golden path ;
   2:  ! UT1 XYZ mm 0.000 0.000 0.000 ;
   3:  ! UT1 ABC deg 0.000 0.000 0.000 ;
   4:  UFRAME_NUM=0 ;
   5:  UTOOL_NUM=1 ;
   6:  ! P1 ;
   7:J P[1] 10% FINE ;
   8:J P[2] 7% CNT50 ;
   9:  ! P2 ;
  10:J P[3] 7% FINE ;
/POS
P[1]{
   GP1:
	UF : 0, UT : 1,
	J1=     0.000 deg,	J2=     0.000 deg,	J3=     0.000 deg,
	J4=     0.000 deg,	J5=    90.000 deg,	J6=     0.000 deg
};
P[2]{
   GP1:
	UF : 0, UT : 1,
	J1=    15.000 deg,	J2=     0.000 deg,	J3=     0.000 deg,
	J4=     0.000 deg,	J5=    90.000 deg,	J6=     0.000 deg
};
P[3]{
   GP1:
	UF : 0, UT : 1,
	J1=    30.000 deg,	J2=     0.000 deg,	J3=     0.000 deg,
	J4=     0.000 deg,	J5=    90.000 deg,	J6=     0.000 deg
};
/END
